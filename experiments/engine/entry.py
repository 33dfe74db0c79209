"""How every ``python -m experiments.X`` ends: Ctrl-C is one line and exit status 130 (the runs resume where they
stopped), a configuration or run error is one line and exit status 2; otherwise ``main``'s status (0 if None).

Configuration errors include a file or folder the study cannot read or write (``--results`` naming a file, a suite
file that is absent or not text) and an override Hydra cannot parse or merge: each is one line naming the path or
the override (``input_error``)."""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import NoReturn

from calib_core.errors import LidarcamError

from .cell import RunnerError

EXIT_INTERRUPTED = 130


class SweepInterrupted(KeyboardInterrupt):
    """Ctrl-C during a sweep; the message says how far it got and that the same command resumes."""


def _first_line(text: object) -> str:
    lines = [ln.strip() for ln in str(text).splitlines() if ln.strip()]
    return lines[0] if lines else ""


def input_error(err: BaseException) -> str | None:
    """The one-line message of an error caused by the study's input (a path, a file's bytes, a Hydra override),
    or None for any other error (a bug: its traceback is shown)."""
    import yaml
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    if isinstance(err, OSError) and err.filename is not None:
        return f"{err.filename}: {err.strerror or _first_line(err)}"
    if isinstance(err, UnicodeDecodeError):
        return f"a file that is not text ({_first_line(err)})"
    if isinstance(err, yaml.YAMLError):
        return f"a file that is not YAML: {_first_line(err)}"
    if isinstance(err, (HydraException, OmegaConfBaseException)):
        cause = err.__cause__ or err.__context__
        extra = f": {_first_line(cause)}" if cause is not None and _first_line(cause) else ""
        return f"{_first_line(err)}{extra}"
    return None


def run_main(main: Callable[[], int | None], prog: str | None = None) -> NoReturn:
    """Run ``main()`` and exit with its status; see the module docstring."""
    spec = getattr(sys.modules["__main__"], "__spec__", None)
    prog = prog or (f"python -m {spec.name}" if spec else "experiments")
    try:
        code = main()
    except KeyboardInterrupt as exc:
        print(f"{prog}: {str(exc) or 'interrupted; the same command resumes'}", file=sys.stderr)
        code = EXIT_INTERRUPTED
    except (LidarcamError, RunnerError) as err:
        print(f"{prog}: error: {err}", file=sys.stderr)
        code = 2
    except Exception as err:
        why = input_error(err)
        if why is None:
            raise
        print(f"{prog}: error: {why}", file=sys.stderr)
        code = 2
    sys.exit(code if isinstance(code, int) else 0)
