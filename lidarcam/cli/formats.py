"""CLI verb ``lidarcam formats``: the board kinds board.yaml takes (with their keys), the camera models and the
camera file forms camera.yaml takes, as docs/dataset.md documents them.

``add_parsers(subparsers)`` registers ``formats``; ``formats_text`` is what it prints.
"""

from __future__ import annotations


def formats_text() -> str:
    """The board kinds, one a line, with the keys that select and describe each; then the camera models and camera
    file forms (``lidarcam.rig.dataset.camera_files.camera_formats``)."""
    from lidarcam.rig.dataset.boards import FORM_SELECTORS, FORMS
    from lidarcam.rig.dataset.camera_files import camera_formats

    lines = ["board.yaml (board kinds, recognised by their keys; docs/dataset.md has an example of each):"]
    for form, (what, need, optional) in FORMS.items():
        sel = FORM_SELECTORS[form]
        keys = ", ".join(([sel] if sel else []) + sorted((k for k in need if k not in sel), key=str.lower))
        opt = ", ".join(sorted(optional, key=str.lower))
        lines.append(f"  {form:<20} {what}: {keys}" + (f" [optional: {opt}]" if opt else ""))
    return "\n".join(lines + ["", "camera.yaml:"] + ["  " + ln for ln in camera_formats()])


def _cmd_formats(args) -> int:
    print(formats_text())
    return 0


def add_parsers(subparsers) -> None:
    """Register the ``formats`` verb on an argparse subparsers object."""
    p = subparsers.add_parser("formats", help="list the board kinds (board.yaml) and camera models (camera.yaml)",
                              description="List the board kinds board.yaml takes and the camera models camera.yaml "
                                          "names, with the keys of each (docs/dataset.md has an example of each).")
    p.set_defaults(func=_cmd_formats)

