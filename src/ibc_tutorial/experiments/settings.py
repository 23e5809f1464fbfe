"""``--set FIELD=VALUE``: one setting of a preset changed from the command line, checked before any work.

A preset (``experiments.agents.presets.Preset``, ``experiments.steering.presets.SteeringPreset``) is
a frozen dataclass whose ``__post_init__`` builds and so validates the library configs it makes
(``CollectConfig``, ``DFOConfig``, ...). ``with_overrides(preset, ["dfo.n_samples=1024"], aliases)``
returns the preset with those fields replaced: a name is a field of the preset (``dfo_samples``) or
the library config's own name for it (``dfo.n_samples``, via the preset's ``CONFIG_FIELDS``); the
value is read as the field's type (an integer, a number, a word, a comma-separated tuple). An unknown
field (the message lists each field once, by the preset's name for it), an unreadable value or a value
the configs refuse is a ``ValueError`` naming ``--set`` and the
field, raised before any work.

``StoredSettings`` is what every preset and the sweep's settings share: their flat JSON form
(``to_dict``, ``from_dict``) and the fields that differ between two of them (``differences``).

``config_from`` builds a library config from a preset by its ``CONFIG_FIELDS`` (the one map between the
two), or from a sub-command's arguments named after the config's fields.
"""

from __future__ import annotations

import dataclasses
import json
from typing import ClassVar


class StoredSettings:
    """Base of the settings dataclasses stored flat as JSON in checkpoints and results folders (the two
    studies' presets, the sweep's settings): tuples are stored as lists and read back as tuples."""

    STORED_DEFAULTS: ClassVar[dict] = {}
    """Values of fields that a stored dict written before they existed meant, whatever today's defaults."""

    def to_dict(self) -> dict:
        """JSON- and checkpoint-friendly form (tuples become lists)."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(self).items()}

    @classmethod
    def from_dict(cls, d: dict):
        """Inverse of ``to_dict``; a field missing from ``d`` takes its ``STORED_DEFAULTS`` value, else its
        default. ValueError if ``d`` is not a dict or names unknown fields."""
        if not isinstance(d, dict):
            raise ValueError(f"a stored {cls.__name__} must be a dict, got {type(d).__name__}")
        unknown = set(d) - {f.name for f in dataclasses.fields(cls)}
        if unknown:
            raise ValueError(f"unknown {cls.__name__} fields {sorted(unknown)}")
        d = {**cls.STORED_DEFAULTS, **d}
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.items()})

    def differences(self, other) -> dict[str, tuple]:
        """Fields whose values differ: ``{field: (self's value, other's value)}`` (the name excluded)."""
        mine, theirs = self.to_dict(), other.to_dict()
        return {k: (mine[k], theirs[k]) for k in mine if k != "name" and mine[k] != theirs[k]}


def config_from(config_type, source, aliases: dict[str, str] | None = None, section: str = "", /, **given):
    """A library config (``config_type``, a dataclass: ``CollectConfig``, ``DFOConfig``, ...) whose fields
    are read from ``source``'s attributes; ``given``: fields set here; the others keep their defaults.

    With ``aliases`` (a preset's ``CONFIG_FIELDS``): the fields of ``section`` ("collect": each
    ``"collect.FIELD": "attribute"`` entry). Without: every field that ``source`` has an attribute of the
    same name for (a sub-command's arguments, named after the config's fields)."""
    if aliases is None:
        names = {f.name: f.name for f in dataclasses.fields(config_type) if hasattr(source, f.name)}
    else:
        prefix = f"{section}."
        names = {k.removeprefix(prefix): v for k, v in aliases.items() if k.startswith(prefix)}
    return config_type(**{field: getattr(source, name) for field, name in names.items()}, **given)


def _parse(name: str, text: str, current):
    """``text`` read as the type of ``current`` (the field's present value)."""
    text = text.strip()
    try:
        if isinstance(current, bool):
            if text.lower() not in ("true", "false", "1", "0"):
                raise ValueError
            return text.lower() in ("true", "1")
        if isinstance(current, int):
            return int(text)
        if isinstance(current, float):
            return float(text)
        if isinstance(current, tuple):
            items = json.loads(text) if text.startswith("[") else [t for t in text.split(",") if t.strip()]
            kind = type(current[0]) if current else str
            return tuple(kind(x.strip() if isinstance(x, str) else x) for x in items)
    except (ValueError, TypeError, json.JSONDecodeError):
        raise ValueError(
            f"--set {name}: cannot read {text!r} as {type(current).__name__} (the field's type)"
        ) from None
    return text


def with_overrides(preset, overrides, aliases: dict[str, str] | None = None):
    """``preset`` with each ``"FIELD=VALUE"`` of ``overrides`` applied (see the module docstring)."""
    aliases = aliases or {}
    names = [f.name for f in dataclasses.fields(preset) if f.name != "name"]
    changes = {}
    for item in overrides or ():
        if not isinstance(item, str) or "=" not in item:
            raise ValueError(f"--set must be FIELD=VALUE, got {item!r}")
        key, text = (part.strip() for part in item.split("=", 1))
        field = aliases.get(key, key)
        if field not in names:
            raise ValueError(
                f"--set: unknown field {key!r}; the fields are {', '.join(sorted(names))} "
                "(a library config's own name for one, such as dfo.n_samples for dfo_samples, is "
                "accepted too)"
            )
        changes[field] = _parse(key, text, getattr(preset, field))
    if not changes:
        return preset
    try:
        return dataclasses.replace(preset, **changes)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"--set {', '.join(overrides)}: {exc}") from None
