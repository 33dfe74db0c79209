"""CLI verb ``lidarcam formats``: the board kinds board.yaml takes (with their keys) and the camera models camera.yaml
names (Kalibr's ``camera_model`` / ``distortion_model`` with their parameters), as docs/dataset.md documents them.

``add_parsers(subparsers)`` registers ``formats``; ``formats_text`` is what it prints.
"""

from __future__ import annotations

DISTORTION_WORDS = {"radtan": "k1, k2, p1, p2[, k3, ...] (OpenCV's order)", "equidistant": "k1, k2, k3, k4",
                    "none": "none"}
"""What ``distortion_coefficients`` holds for each ``distortion_model``."""


def formats_text() -> str:
    """The board kinds and camera models, one a line, with the keys that select and describe each."""
    from calib_core.data.cameras import CAMERA_MODELS, MODEL_NAMES
    from lidarcam.rig.dataset.boards import FORM_SELECTORS, FORMS
    from lidarcam.rig.dataset.yaml_files import PINHOLE_DISTORTIONS

    lines = ["board.yaml (board kinds; docs/dataset.md):"]
    for form, (what, need, optional) in FORMS.items():
        sel = FORM_SELECTORS[form]
        keys = ", ".join(([sel] if sel else []) + sorted((k for k in need if k not in sel), key=str.lower))
        opt = ", ".join(sorted(optional, key=str.lower))
        lines.append(f"  {form:<20} {what}: {keys}" + (f" [optional: {opt}]" if opt else ""))
    lines += ["", "camera.yaml (camera models; docs/dataset.md): image_width, image_height, camera_matrix, "
              "distortion_coefficients, then:"]
    names = {pair: name for name, pair in MODEL_NAMES.items()}
    for (cm, dm), cls in CAMERA_MODELS.items():
        params = ", ".join(cls.param_names)
        keys = "no model keys (or camera_model: pinhole)" if (cm, dm) == ("pinhole", "radtan") else \
            f"camera_model: {cm}, distortion_model: {dm}" + (f", {params}" if params else "")
        also = f" (distortion_model may also read {', '.join(PINHOLE_DISTORTIONS[1:])})" if dm == "radtan" else ""
        lines.append(f"  {names[(cm, dm)]:<20} {keys}; distortion {DISTORTION_WORDS[dm]}{also}")
    return "\n".join(lines)


def _cmd_formats(args) -> int:
    print(formats_text())
    return 0


def add_parsers(subparsers) -> None:
    """Register the ``formats`` verb on an argparse subparsers object."""
    p = subparsers.add_parser("formats", help="list the board kinds (board.yaml) and camera models (camera.yaml)",
                              description="List the board kinds board.yaml takes and the camera models camera.yaml "
                                          "names, with the keys of each (docs/dataset.md has an example of each).")
    p.set_defaults(func=_cmd_formats)

