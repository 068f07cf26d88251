"""The JSON schemas of captures: ``/cm/<channel>/capture_waveform`` (cmsensord.CaptureWaveform) and
``/cm/<channel>/capture_spectrum``, ``/cm/<channel>/capture_envelope`` (cmsensord.CaptureSpectrum).

One message of each per channel and capture, all stamped at the trigger; arrays of
plain numbers (a lost sample is 0 and its index is in ``lost``), no union types.  A RAW
capture's spectra carry the shaft speed and the frequencies to mark (``marks``: 1x and
the bearings' defect lines, :mod:`cmsensord.monitor.capture_marks`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

__all__ = ["capture_waveform_schema", "capture_spectrum_schema", "capture_topics"]


def capture_topics(channel: str) -> tuple[str, str, str]:
    """(waveform, spectrum, envelope spectrum) topics of ``channel``."""
    return (f"/cm/{channel}/capture_waveform", f"/cm/{channel}/capture_spectrum",
            f"/cm/{channel}/capture_envelope")


def _trigger() -> dict[str, Any]:
    return {"type": "object", "description": "what triggered the capture",
            "properties": {"kind": {"type": "string", "description": "event kind, or periodic"},
                           "message": {"type": "string", "description": "the event's message"}},
            "required": ["kind", "message"]}


def _mark() -> dict[str, Any]:
    return {"type": "object", "description": "a frequency marked on the spectrum",
            "properties": {
                "label": {"type": "string", "description": "1x, or <bearing> FTF / BPFO / BPFI / BSF"},
                "kind": {"type": "string", "enum": ["shaft", "ftf", "bpfo", "bpfi", "bsf"],
                         "description": "shaft speed, or which defect frequency"},
                "bearing": {"type": "string", "description": "the bearing's name (absent for the shaft)"},
                "freq_hz": {"type": "number", "minimum": 0, "description": "the line's frequency [Hz]"}},
            "required": ["label", "kind", "freq_hz"]}


def capture_waveform_schema(time: Callable[[], dict], obj: Callable[..., dict]) -> dict[str, Any]:
    return obj(
        "cmsensord.CaptureWaveform",
        "The signal of one channel from pre_s before to post_s after a trigger (RAW: samples in m/s^2; "
        "RMS mode: the 100 Hz block RMS).",
        {
            "timestamp": time(),
            "channel": {"type": "string", "description": "configured channel name"},
            "trigger": _trigger(),
            "source": {"type": "string", "enum": ["raw", "rms"], "description": "RAW samples or block RMS"},
            "sample_rate_hz": {"type": "number", "description": "samples per second", "minimum": 0},
            "first_sample": {"type": "integer", "description": "board index of the first sample (RAW: the "
                             "sample counter t0; RMS: t0 / block length)"},
            "pre_s": {"type": "number", "description": "seconds before the trigger", "minimum": 0},
            "post_s": {"type": "number", "description": "seconds after the trigger", "minimum": 0},
            "unit": {"type": "string", "description": "unit of samples"},
            "missing": {"type": "integer", "description": "samples lost", "minimum": 0},
            "samples": {"type": "array", "items": {"type": "number"},
                        "description": "the signal, pre_s + post_s seconds (0 where a sample was lost)"},
            "lost": {"type": "array", "items": {"type": "integer"},
                     "description": "indices of the lost samples in samples (absent: none)"},
        },
        ["timestamp", "channel", "trigger", "source", "sample_rate_hz", "first_sample", "pre_s", "post_s",
         "unit", "samples"],
    )


def capture_spectrum_schema(time: Callable[[], dict], obj: Callable[..., dict]) -> dict[str, Any]:
    return obj(
        "cmsensord.CaptureSpectrum",
        "The amplitude spectrum (or the envelope's) of one capture: amplitude[k] at freq_start_hz + "
        "k * freq_step_hz.",
        {
            "timestamp": time(),
            "channel": {"type": "string", "description": "configured channel name"},
            "trigger": _trigger(),
            "kind": {"type": "string", "enum": ["spectrum", "envelope"], "description": "which spectrum"},
            "freq_start_hz": {"type": "number", "description": "frequency of the first bin [Hz]"},
            "freq_step_hz": {"type": "number", "description": "bin spacing [Hz]", "minimum": 0},
            "band_hz": {"type": "array", "items": {"type": "number"}, "minItems": 2, "maxItems": 2,
                        "description": "envelope: the band demodulated [Hz] (indicators.envelope_band_hz, "
                                       "else 0.08-0.4 fs: the indicators' band)"},
            "unit": {"type": "string", "description": "unit of amplitude"},
            "amplitude": {"type": "array", "items": {"type": "number"},
                          "description": "RMS amplitude per bin: a sine of RMS a reads a at its frequency (envelope: "
                                         "a modulation of the envelope reads its RMS, as envelope_rms counts it)"},
            "shaft_speed_rpm": {"type": "number", "minimum": 0,
                                "description": "RAW: mean shaft speed over the capture [rpm] (absent: unknown)"},
            "speed_source": {"type": "string", "enum": ["tacho", "config"],
                             "description": "where the shaft speed came from (indicators.rpm: config)"},
            "marks": {"type": "array", "items": _mark(),
                      "description": "RAW: the shaft's 1x and each bearing's defect lines at shaft_speed_rpm "
                                     "within the spectrum's range (absent: the speed is unknown)"},
        },
        ["timestamp", "channel", "trigger", "kind", "freq_start_hz", "freq_step_hz", "unit", "amplitude"],
    )
