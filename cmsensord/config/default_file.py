"""The commented default configuration file (every key, its default and meaning).

The repository keeps it as ``config/default.yaml``; the build copies it into the
package as ``cmsensord/config/default.yaml`` (``setup.py``), so an installed wheel has
it. ``cmsensord config --default`` prints it.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

__all__ = ["default_yaml"]

_REPOSITORY_COPY = Path(__file__).resolve().parents[2] / "config" / "default.yaml"


def default_yaml() -> str | None:
    """The text of the default configuration: the package's copy (an installed wheel), else the
    repository's (a checkout, an editable install); None when neither is there."""
    packaged = resources.files("cmsensord.config") / "default.yaml"
    if packaged.is_file():
        return packaged.read_text(encoding="utf-8")
    if _REPOSITORY_COPY.is_file():
        return _REPOSITORY_COPY.read_text(encoding="utf-8")
    return None
