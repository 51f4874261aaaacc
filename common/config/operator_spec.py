"""The operator spec string ``kind:key=value,...`` of the simulated rig's operator models
(haptic.master.simulated_rig.operator): its grammar, defaults and checks, as plain data, so the
configuration can validate ``[master.sim] operator`` and the ``[lockstep]`` operators
without importing the master package."""

from __future__ import annotations

import math

from haptic.common.model.errors import ConfigError

#: The operator kinds (haptic.master.simulated_rig.operator documents each).
OPERATOR_KINDS = ("constant", "regulate", "track")

_DEFAULTS: dict[str, dict[str, float | str]] = {
    "constant": {"fx": 0.0, "fy": 0.0, "onset": 0.0, "rise": 0.0},
    "regulate": {"fx": 3.6, "fy": 0.0, "kp": 0.5, "ki": 4.0, "lag": 0.1, "max": 20.0,
                 "onset": 0.0, "rise": 0.0},
    "track": {"shape": "ramp", "vx": 0.0, "vy": 0.0, "ax": 0.0, "ay": 0.0, "freq": 0.5,
              "kp": 200.0, "kd": 20.0, "max": 20.0, "onset": 0.0},
}
_NON_NEGATIVE = {"onset", "rise", "lag", "max", "kp", "ki", "kd", "freq"}


def parse_operator_params(spec: str, key: str = "operator") -> tuple[str, dict[str, float | str]]:
    """Parse ``kind:key=value,...`` into the kind and its parameters (defaults filled in).

    Raises :class:`ConfigError` (naming ``key``) for an unknown kind or parameter, a value
    that is not a finite number, or a negative time, gain or limit.
    """
    kind, _, rest = spec.strip().partition(":")
    kind = kind.strip()
    if kind not in _DEFAULTS:
        raise ConfigError(key, f"operator kind must be one of {', '.join(OPERATOR_KINDS)} "
                               f"(got {kind!r} in {spec!r})")
    params = dict(_DEFAULTS[kind])
    for item in filter(None, (part.strip() for part in rest.split(","))):
        name, equals, text = item.partition("=")
        name, text = name.strip(), text.strip()
        if not equals or name not in params:
            raise ConfigError(key, f"unknown {kind} operator parameter {item!r}; expected "
                                   f"{', '.join(params)}")
        if name == "shape":
            if text not in ("ramp", "sine"):
                raise ConfigError(key, f"track shape must be ramp or sine (got {text!r})")
            params[name] = text
            continue
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            raise ConfigError(key, f"operator parameter {name} must be a finite number "
                                   f"(got {text!r})")
        if name in _NON_NEGATIVE and value < 0.0:
            raise ConfigError(key, f"operator parameter {name} must be >= 0 (got {value:g})")
        params[name] = value
    return kind, params



def check_operator_spec(spec: str) -> str | None:
    """Schema hook: an error message for a bad spec, ``None`` when it parses."""
    try:
        parse_operator_params(spec)
    except ConfigError as error:
        return str(error).split(": ", 1)[-1]
    return None
