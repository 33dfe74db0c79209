"""How every ``python -m experiments.X`` ends: Ctrl-C is one line and exit status 130 (the runs resume where they
stopped), a configuration or run error is one line and exit status 2; otherwise ``main``'s status (0 if None)."""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import NoReturn

from calib_core.errors import LidarcamError

from .cell import RunnerError

EXIT_INTERRUPTED = 130


class SweepInterrupted(KeyboardInterrupt):
    """Ctrl-C during a sweep; the message says how far it got and that the same command resumes."""


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
    sys.exit(code if isinstance(code, int) else 0)
