"""Hydra overrides checked before a run: an override that does not parse, deletes a config group, or names a key
or a group option that does not exist is one line (with the closest existing one: "did you mean ..."), instead of
Hydra's stock message and its ``+key`` hint; a study refuses overrides of what its own flags set
(``refuse_flag_overrides``)."""

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


def override_key(override: str) -> str:
    """The key an override sets, without its ``+``/``++``/``~`` prefix (``~scene`` -> ``scene``)."""
    return override.partition("=")[0].lstrip("+~")


def parse_errors(overrides: Sequence[str]) -> None:
    """ConfigError naming the first override Hydra's grammar does not parse."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import HydraException

    parser = OverridesParser.create()
    for o in overrides:
        try:
            parser.parse_overrides([o])
        except HydraException as err:
            why = " ".join(str(err).split("See https://")[0].split())
            raise ConfigError(f"{o}: not a Hydra override ({why})") from None


def refuse_flag_overrides(overrides: Sequence[str], flags: dict[str, str]) -> None:
    """ConfigError for an override of a key the study sets from its own flag (``{"results_dir": "--results"}``):
    given both ways, the rows and the tables would go to different places."""
    for o in overrides:
        if (key := override_key(o)) in flags:
            raise ConfigError(f"{o}: this study sets {key!r} from {flags[key]}; give it there")


def check_overrides(overrides: Sequence[str], compose, conf_dir: Path) -> None:
    """ConfigError naming the first override that does not parse, deletes a config group, or whose key or group
    option does not exist. ``compose(overrides)`` composes the primary config of ``conf_dir`` (the caller holds
    Hydra's initialisation); appended keys (``+key=...``), other deletions (``~key``) and ``hydra.*`` keys are
    left to Hydra, whose composition errors are one line too."""
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    parse_errors(overrides)
    groups = group_options(conf_dir)
    for o in overrides:
        if o.startswith("~") and override_key(o) in groups:
            raise ConfigError(f"{o}: every setting needs a {override_key(o)!r}; choose one of its options "
                              f"({', '.join(groups[override_key(o)])}) instead of deleting it")
    choices = []
    for o in overrides:
        key, eq, value = o.partition("=")
        if eq and key in groups:
            for v in value.split(","):
                if v.strip() not in groups[key]:
                    raise ConfigError(f"{o}: no option {v.strip()!r} in config group {key!r}"
                                      f"{_hint(v.strip(), groups[key])} (options: {', '.join(groups[key])})")
            choices.append(f"{key}={value.split(',')[0]}")
    try:
        keys = _keys(OmegaConf.to_container(compose(choices), resolve=False))
    except (HydraException, OmegaConfBaseException) as err:
        raise ConfigError(composition_error(err)) from None
    for o in overrides:
        key, eq, _ = o.partition("=")
        if not eq or key in groups or key.startswith(("+", "~", "hydra.", "hydra/")):
            continue
        if key not in keys:
            raise ConfigError(f"{o}: unknown key {key!r}{_hint(key, keys)}")


def composition_error(err: BaseException) -> str:
    """Hydra's composition error as one line, with its cause (``Error merging override scene.n_boards=abc:
    Value 'abc' of type 'str' could not be converted to Integer``)."""
    def first(e) -> str:
        return next((ln.strip() for ln in str(e).splitlines() if ln.strip()), type(e).__name__)
    cause = err.__cause__ or err.__context__
    return first(err) + (f": {first(cause)}" if cause is not None else "")
