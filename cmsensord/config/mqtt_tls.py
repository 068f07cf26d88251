"""The TLS context of the MQTT connection, from ``mqtt.ca_file``, ``certfile`` and ``keyfile``.

The configuration loader builds it once, so that a file holding no certificate, a key that
is not the certificate's or a key behind a passphrase is a configuration error naming the
file; the publisher builds it again at each connection, so renewed files are used.
"""

from __future__ import annotations

import re
import ssl
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .mqtt import MqttConfig

__all__ = ["TlsFileError", "tls_context"]

_PEM_LABEL = re.compile(rb"-----BEGIN ([A-Z0-9 ]{1,40})-----")
#: how much of a file is read to say what it holds
_PEEK_BYTES = 1 << 16


class TlsFileError(ValueError):
    """One TLS file cannot be used: ``key`` is the setting (``ca_file``, ``certfile`` or
    ``keyfile``), ``path`` its file, ``reason`` what is wrong; ``str()`` is one line."""

    def __init__(self, key: str, path: str, reason: str) -> None:
        self.key, self.path, self.reason = key, path, reason
        super().__init__(f"mqtt.{key}: {path}: {reason}")


def _holds(path: str) -> str:
    """What the file holds, for a message: its PEM blocks (``RSA PRIVATE KEY``), ``empty``
    or ``not PEM``."""
    with open(path, "rb") as f:
        head = f.read(_PEEK_BYTES)
    labels = list(dict.fromkeys(m.decode() for m in _PEM_LABEL.findall(head)))
    if labels:
        return "it holds " + ", ".join(labels)
    return "it is empty" if not head.strip() else "it is not PEM (DER? openssl x509 -inform der converts it)"


def _no_certificate(key: str, path: str, what: str) -> TlsFileError:
    return TlsFileError(key, path, f"no certificate in it ({_holds(path)}): give {what}, "
                        "PEM (-----BEGIN CERTIFICATE-----)")


def _client_pair(context: ssl.SSLContext, certfile: str, keyfile: str | None) -> None:
    """The client certificate and its key into ``context``; TlsFileError naming the file at fault."""
    try:
        ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT).load_verify_locations(certfile)
    except ssl.SSLError:
        raise _no_certificate("certfile", certfile, "the client certificate") from None
    asked: list[bool] = []

    def passphrase() -> bytes:
        asked.append(True)
        return b""

    try:
        context.load_cert_chain(certfile, keyfile, passphrase)
    except ssl.SSLError as err:
        path = keyfile or certfile
        if err.reason == "KEY_VALUES_MISMATCH":
            reason = (f"not the key of mqtt.certfile {certfile} (KEY_VALUES_MISMATCH): give the key "
                      "the certificate was made for")
        elif asked:
            reason = ("the key is encrypted (it asks for a passphrase): give it unencrypted "
                      "(openssl pkey -in KEY -out PLAIN), readable by cmsensord only")
        else:
            reason = f"no private key in it ({_holds(path)}): give the client's key, PEM (-----BEGIN PRIVATE KEY-----)"
        raise TlsFileError("keyfile" if keyfile else "certfile", path, reason) from None


def tls_context(cfg: MqttConfig) -> ssl.SSLContext | None:
    """None without ``ca_file`` and ``certfile`` (plain MQTT); else a client context that checks
    the broker's certificate and host name against ``ca_file`` (the system's CAs without it) and
    presents ``certfile``/``keyfile`` when given. OSError: a file cannot be read; TlsFileError:
    a file that holds no certificate, no key, or not the certificate's key."""
    if cfg.ca_file is None and cfg.certfile is None:
        return None
    context = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)    # CERT_REQUIRED, check_hostname
    if cfg.certfile is not None:
        _client_pair(context, cfg.certfile, cfg.keyfile)
    if cfg.ca_file is None:
        context.load_default_certs()
        return context
    try:
        context.load_verify_locations(cfg.ca_file)
    except ssl.SSLError:
        raise _no_certificate("ca_file", cfg.ca_file, "the broker's CA certificate") from None
    return context
