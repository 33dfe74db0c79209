"""Hydra overrides checked before a run: a key or a group option that does not exist is one line with the
closest existing one ("did you mean ..."), instead of Hydra's stock message and its ``+key`` hint."""

from __future__ import annotations

import difflib
from collections.abc import Sequence
from pathlib import Path

from omegaconf import OmegaConf

from .validate import ConfigError


def group_options(conf_dir: Path) -> dict[str, list[str]]:
    """Config group (``scene``, ``hydra/launcher``, ...) -> its options (the YAML files' stems)."""
    out: dict[str, list[str]] = {}
    for f in sorted(conf_dir.rglob("*.yaml")):
        if f.parent != conf_dir:
            out.setdefault(str(f.parent.relative_to(conf_dir)), []).append(f.stem)
    return out


def _keys(cfg, prefix: str = "") -> set[str]:
    out = set()
    for k, v in cfg.items():
        name = f"{prefix}{k}"
        out.add(name)
        if isinstance(v, dict):
            out |= _keys(v, name + ".")
    return out


def _hint(word: str, known) -> str:
    close = difflib.get_close_matches(word, list(known), n=1, cutoff=0.6)
    return f"; did you mean {close[0]!r}?" if close else ""


def check_overrides(overrides: Sequence[str], compose, conf_dir: Path) -> None:
    """ConfigError naming the first override whose key or group option does not exist. ``compose(overrides)``
    composes the primary config of ``conf_dir`` (the caller holds Hydra's initialisation); appended keys (``+key=...``),
    deletions (``~key``) and ``hydra.*`` keys are left to Hydra."""
    groups = group_options(conf_dir)
    choices = []
    for o in overrides:
        key, eq, value = o.partition("=")
        if eq and key in groups:
            for v in value.split(","):
                if v.strip() not in groups[key]:
                    raise ConfigError(f"{o}: no option {v.strip()!r} in config group {key!r}"
                                      f"{_hint(v.strip(), groups[key])} (options: {', '.join(groups[key])})")
            choices.append(f"{key}={value.split(',')[0]}")
    keys = _keys(OmegaConf.to_container(compose(choices), resolve=False))
    for o in overrides:
        key, eq, _ = o.partition("=")
        if not eq or key in groups or key.startswith(("+", "~", "hydra.", "hydra/")):
            continue
        if key not in keys:
            raise ConfigError(f"{o}: unknown key {key!r}{_hint(key, keys)}")
