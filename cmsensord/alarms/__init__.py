"""The alarm manager (pure: values and stream time in, alarm transitions out).

* :mod:`.state` -- one alarm: on- and off-delays, latching until acknowledged;
* :mod:`.exceedance` -- a value against alert and danger levels with a deadband;
* :mod:`.operating` -- running / stopped, start-up and coast-down suppression;
* :mod:`.levels` -- a rule's levels on a channel: absolute, ISO zone boundary or
  k x the learned baseline, per speed band;
* :mod:`.manager` -- the rules of the configuration over the channels, N-of-M
  voting, the alarm table and acknowledgements;
* :mod:`.saved` -- the alarm state an operator relies on as saved records, put back
  into a new manager (a daemon's restart).

The monitoring chain feeds it (:mod:`cmsensord.monitor.alarms`); every time is a
stamp of the stream, so a replay raises the same alarms as the live run.
"""

from .manager import AlarmManager, Judged, Transition
from .state import LEVELS

__all__ = ["AlarmManager", "Judged", "Transition", "LEVELS"]
