"""The one registry of trackingbox's settings read from the environment (``TRACKINGBOX_*``).

Every switch has one :class:`Setting` here: its name, type, default, what it
does and the environment variable that sets it. The package reads them only
through :func:`get`, which parses and checks the variable each time it is
asked (a test or a notebook may change the environment between runs); a value
that does not parse is a :class:`ConfigError` naming the variable, the value
and what it takes. ``trackingbox config`` lists them (:func:`describe`) and the
README's table is :func:`markdown_table`.

>>> get("fmu_timeout", {"TRACKINGBOX_FMU_TIMEOUT": "2.5"})
2.5
>>> get("native", {"TRACKINGBOX_NATIVE": "0"}), get("native", {})
(False, True)
>>> get("fmu_timeout", {"TRACKINGBOX_FMU_TIMEOUT": "soon"})
Traceback (most recent call last):
...
trackingbox.config.ConfigError: TRACKINGBOX_FMU_TIMEOUT='soon' is not a number of seconds > 0
"""
from __future__ import annotations

import math
import os
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Literal

from .errors import TrackingError

Kind = Literal["bool", "int", "float", "str", "path"]
Source = Literal["default", "env"]

_TRUE = ("1", "true", "yes", "on")
_FALSE = ("0", "false", "no", "off")


class ConfigError(TrackingError, ValueError):
    """An environment variable of the registry holds a value it does not take."""


@dataclass(frozen=True)
class Setting:
    """One setting: *name* (lower case) read from the environment variable *env*."""

    name: str
    kind: Kind
    default: Any
    doc: str
    #: what a valid value is, in words (the error says it), and the check
    takes: str = ""
    check: Callable[[Any], bool] | None = None
    #: the value is a secret: listed as set or not, never shown
    secret: bool = False
    #: set by trackingbox itself for a child process, not by users
    internal: bool = False
    #: the variable's text as it is: not stripped, and an empty value is a value (a password)
    raw: bool = False

    @property
    def env(self) -> str:
        return "TRACKINGBOX_" + self.name.upper()

    def parse(self, text: str) -> Any:
        """The value of the variable's *text* (stripped); :class:`ConfigError` if it does not take it."""
        raw = text.strip()
        try:
            if self.kind == "bool":
                low = raw.lower()
                if low not in _TRUE + _FALSE:
                    raise ValueError
                value: Any = low in _TRUE
            elif self.kind == "int":
                value = int(raw)
            elif self.kind == "float":
                value = float(raw)
            else:
                value = raw
        except ValueError:
            raise ConfigError(f"{self.env}={text!r} is not {self.takes or _KIND_WORDS[self.kind]}") from None
        if self.check is not None and not self.check(value):
            raise ConfigError(f"{self.env}={text!r} is not {self.takes or _KIND_WORDS[self.kind]}")
        return value


_KIND_WORDS = {"bool": "one of 1/0, true/false, yes/no, on/off", "int": "an integer", "float": "a number",
               "str": "a text", "path": "a path"}


def _positive(x: float) -> bool:
    return x > 0 and math.isfinite(x)


#: Every setting, in the order ``trackingbox config`` lists them.
SETTINGS: tuple[Setting, ...] = (
    Setting("supervise", "bool", True,
            "run each command in a forked child watched by the parent: a crash or exit() of an FMU's binary "
            "is one error line naming the signal and the FMI function"),
    Setting("watchdog", "bool", True,
            "under the supervisor, end a run whose FMI call takes longer than the FMU timeout "
            "(one error line, exit 2)"),
    Setting("fmu_timeout", "float", 60.0,
            "seconds one FMI call may take, in the canary and under the watchdog",
            takes="a number of seconds > 0", check=_positive),
    Setting("canary", "bool", True,
            "run an FMU's first calls once in a forked child before its binary is loaded in this process"),
    Setting("fmu_max_bytes", "int", 2 << 30,
            "most bytes an FMU archive may inflate to when extracted",
            takes="a number of bytes > 0", check=lambda x: x > 0),
    Setting("native", "bool", True,
            "let FMUModel.stepper() choose the native (C) model-exchange stepper where it can; "
            "false: the Python path"),
    Setting("native_rows", "bool", True,
            "run batches of tracking rows in C where both twins run on the native stepper; "
            "false: every row in Python"),
    Setting("frontend_timeout", "float", 600.0,
            "seconds the embedded compiler's front end (rumoca) may take before it counts as hung",
            takes="a number of seconds > 0", check=_positive),
    Setting("frontend_stack_mb", "int", 64,
            "native stack (MiB) of the thread the embedded compiler's front end runs on",
            takes="a number of MiB >= 1", check=lambda x: x >= 1),
    Setting("frontend_cache", "bool", True,
            "keep flattened models on disk under the cache folder, keyed by the content of every file "
            "the model reaches (false: flatten every time)"),
    Setting("patch_cache", "bool", True,
            "keep the FMUs of diagnose's patched twins under the cache folder, keyed by the content of the patch, "
            "the twin's source, the libraries and the compiler (false: compile every patch in every diagnosis)"),
    Setting("cache_dir", "path", "",
            "folder of trackingbox's caches (empty: $XDG_CACHE_HOME/trackingbox or ~/.cache/trackingbox)"),
    Setting("msl", "path", "",
            "the Modelica Standard Library package scripts/msl compiles (empty: ../shared/msl/Modelica beside the "
            "repository)"),
    Setting("msl_reference", "path", "",
            "the MSL reference results scripts/msl compares with (empty: ../shared/msl-reference beside "
            "the repository)"),
    Setting("cc_opt", "str", "",
            "gcc optimisation flag for an FMU's generated C (empty: -O1, and -O0 for very large sources)",
            takes="a gcc optimisation flag (-O0 .. -O3, -Os, -Og)",
            check=lambda s: s == "" or re.fullmatch(r"-O[0-3sg]?", s) is not None),
    Setting("compliance", "path", "",
            "the Modelica compliance suite scripts/compliance runs (empty: "
            "../shared/modelica-compliance/ModelicaCompliance beside the repository)"),
    Setting("opcua_credentials", "path", "",
            "file with 'user = ...' and 'password = ...' lines for OPC UA (mode 0600 or stricter)"),
    Setting("opcua_user", "str", None, "OPC UA user name (without a credentials file)", raw=True),
    Setting("opcua_password", "str", None, "OPC UA password (without a credentials file)", secret=True,
            raw=True),
    Setting("view_credentials", "path", "",
            "file with 'user = ...' and 'password = ...' lines for the live view's HTTP basic auth "
            "(mode 0600 or stricter; needed off loopback)"),
    Setting("view_user", "str", None, "live view user name (without a credentials file)", raw=True),
    Setting("view_password", "str", None, "live view password (without a credentials file)", secret=True,
            raw=True),
    Setting("chromium", "path", "",
            "the Chromium the live view's screenshots and browser test drive (empty: chromium or "
            "chromium-browser on PATH)"),
    Setting("supervisor_note", "path", "",
            "file where a supervised child notes the FMU it opened last (set by the supervisor)", internal=True),
    Setting("supervisor_outputs", "path", "",
            "file where a supervised child lists the output folders it is creating (set by the supervisor)",
            internal=True),
)

_BY_NAME = {s.name: s for s in SETTINGS}


def setting(name: str) -> Setting:
    """The :class:`Setting` called *name* (``KeyError`` for a name the registry does not have)."""
    return _BY_NAME[name]


def get(name: str, environ: Mapping[str, str] | None = None) -> Any:
    """The value of setting *name*: its environment variable's, parsed and checked, else the default.

    An empty variable counts as unset. *environ* defaults to ``os.environ``.
    """
    s = _BY_NAME[name]
    text = (os.environ if environ is None else environ).get(s.env)
    if s.raw:
        return s.default if text is None else text
    if text is None or not text.strip():
        return s.default
    return s.parse(text)


def source(name: str, environ: Mapping[str, str] | None = None) -> Source:
    """``"env"`` when setting *name* comes from its environment variable, else ``"default"``."""
    s = _BY_NAME[name]
    text = (os.environ if environ is None else environ).get(s.env)
    return "env" if text is not None and (s.raw or text.strip()) else "default"


def check_all(environ: Mapping[str, str] | None = None) -> None:
    """Refuse every invalid variable at once (one :class:`ConfigError` naming each)."""
    problems = []
    for s in SETTINGS:
        try:
            get(s.name, environ)
        except ConfigError as exc:
            problems.append(str(exc))
    if problems:
        raise ConfigError("; ".join(problems))


def describe(environ: Mapping[str, str] | None = None) -> list[dict[str, Any]]:
    """One record per setting: name, variable, type, value, source, default and doc (secrets hidden).

    An invalid variable's record has ``value = None`` and the problem in ``error``.
    """
    out = []
    for s in SETTINGS:
        record: dict[str, Any] = {"name": s.name, "env": s.env, "type": s.kind, "default": s.default,
                                  "source": source(s.name, environ), "doc": s.doc, "internal": s.internal}
        try:
            value = get(s.name, environ)
            record["value"] = ("(set)" if record["source"] == "env" else "") if s.secret else value
        except ConfigError as exc:
            record["value"], record["error"] = None, str(exc)
        out.append(record)
    return out


def markdown_table() -> str:
    """The README's table of the settings (variable, type, default, what it does)."""
    rows = ["| variable | type | default | what it does |", "|---|---|---|---|"]
    for s in SETTINGS:
        default = (("on" if s.default else "off") if s.kind == "bool"
                   else "(unset)" if s.default in ("", None) else f"`{s.default}`")
        doc = s.doc + (" *(internal)*" if s.internal else "")
        rows.append(f"| `{s.env}` | {s.kind} | {default} | {doc} |")
    return "\n".join(rows) + "\n"
