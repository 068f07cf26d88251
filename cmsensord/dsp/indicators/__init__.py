"""Vibration indicators a maintenance team reads beside the severity index (pure DSP).

Per channel and interval (:mod:`.interval` puts them together):

* :mod:`.statistics` -- acceleration RMS, peak, crest factor, kurtosis;
* :mod:`.spectrum` -- the Hann power spectrum the next two read;
* :mod:`.velocity` -- velocity RMS [mm/s] in the ISO 10816-3 band, by integration in
  the frequency domain;
* :mod:`.iso_zones` -- ISO 10816-3 / 20816-3 zones A-D and the baseline-relative alarm;
* :mod:`.envelope` -- acceleration enveloping, envelope RMS, envelope spectrum lines;
* :mod:`.bearings` -- the defect frequencies FTF, BPFO, BPFI, BSF of a bearing;
* :mod:`.bands` -- band RMS in Hz or in orders;
* :mod:`.gapped` -- all of them of a record missing a small share of its samples.

numpy only (no scipy): the daemon imports this.
"""

from .interval import Band, Bearing, IndicatorRecord, Setup, compute, compute_many

__all__ = ["Band", "Bearing", "IndicatorRecord", "Setup", "compute", "compute_many"]
