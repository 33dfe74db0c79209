"""A generated corpus of hostile inputs, each with the outcome expected of the library.

Every case is a ``Case``: a file's bytes (``data``), made from simulated observations, and what must happen:

- ``refused``: ``load_observations`` raises ObservationError, one line naming the file (and ``field`` when given);
- ``correct``: the file loads and the default method's answer is ok and valid against the truth (and, where
  ``cause`` is given, a warning names that cause);
- ``flagged``: the file loads; the data are physically wrong, so the default method's answer must be ``ok=False``
  (its reason names a board and a test) and, where ``cause`` is given, a warning names that cause;
- ``warned``: the answer carries a warning naming ``cause`` (mirrored scans fit an upside-down lidar exactly; a
  board set listed twice);
- ``undetectable``: board poses scaled by 15% (focal length or square size off) can leave the scans consistent
  with a wrong answer; without corner observations the verdict cannot always see it. Counted, not asserted:
  when the answer is contradicted, the cause must be named.

Classes: bytes (encodings, binary, truncation, nesting), types (JSON types, booleans and strings for numbers,
meta), tolerance (rounded rotations, closed outlines, BOM), limits (boards, points, vertices), physics (units,
mispaired, mirrored, behind the camera, scaled poses, stray points; copies: repeated points, boards listed twice).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from calib_core import observations_to_dict
from calib_core.data.observations import MAX_BOARDS, MAX_OUTLINE_VERTICES, MAX_SCAN_POINTS
from simulate import SimOptions, generate


@dataclass(frozen=True)
class Case:
    name: str
    kind: str            # bytes, types, tolerance, limits, physics
    data: bytes
    expect: str          # refused, correct, flagged, not_silent
    field: str | None = None
    cause: str | None = None


def base(n_boards: int = 6, seed: int = 0, noise_mm: float = 20.0, lidar_res_deg: float = 0.25) -> dict:
    obs = generate(SimOptions(n_boards=n_boards, noise_mm=noise_mm, lidar_res_deg=lidar_res_deg), seed=seed,
                   trial=seed)
    return observations_to_dict(obs)


def dump(d) -> bytes:
    return json.dumps(d).encode()


def _edit(d: dict, fn: Callable[[dict], None]) -> bytes:
    d = json.loads(json.dumps(d))
    fn(d)
    return dump(d)


def byte_cases(d: dict) -> list[Case]:
    good = dump(d)
    text = good.decode()
    rng = np.random.default_rng(7)
    out = [
        Case("utf8_bom", "bytes", b"\xef\xbb\xbf" + good, "correct"),
        Case("utf16_le_bom", "bytes", text.encode("utf-16"), "refused"),
        Case("utf16_be", "bytes", text.encode("utf-16-be"), "refused"),
        Case("utf32", "bytes", text.encode("utf-32"), "refused"),
        Case("latin1_in_meta", "bytes", good.replace(b'"generator"', b'"gen\xe9rator"'), "refused"),
        Case("nul_bytes", "bytes", good[:100] + b"\x00" * 8 + good[100:], "refused"),
        Case("empty", "bytes", b"", "refused"),
        Case("whitespace", "bytes", b"  \n\t ", "refused"),
        Case("deep_nesting", "bytes", b"[" * 100_000 + b"]" * 100_000, "refused"),
        Case("deep_objects", "bytes", b'{"a":' * 50_000 + b"1" + b"}" * 50_000, "refused"),
        Case("huge_number", "bytes", good.replace(b"[[", b"[[1e400, ", 1), "refused"),
        Case("nan_literal", "bytes", _edit(d, lambda x: x["boards"][1]["scan"][0].__setitem__(0, float("nan"))),
             "refused", "scan"),
        Case("infinity_literal", "bytes", good.replace(b'"T_cam_board": [[', b'"T_cam_board": [[Infinity, ', 1),
             "refused"),
    ]
    for k, frac in enumerate((0.1, 0.5, 0.9, 0.999)):
        out.append(Case(f"truncated_{k}", "bytes", good[: int(len(good) * frac)], "refused"))
    for k in range(6):
        out.append(Case(f"random_binary_{k}", "bytes", rng.integers(0, 256, 200 + 300 * k, dtype=np.uint8).tobytes(),
                        "refused"))
    out.append(Case("png_header", "bytes", b"\x89PNG\r\n\x1a\n" + rng.integers(0, 256, 500, dtype=np.uint8).tobytes(),
                    "refused"))
    return out


def type_cases(d: dict) -> list[Case]:
    def b1(key, value):
        return lambda x: x["boards"][1].__setitem__(key, value)

    def leaf(key, value):
        return lambda x: x["boards"][2][key][0].__setitem__(1, value)

    spec = [
        ("top_list", lambda x: x.clear() or None, None),
        ("schema_missing", lambda x: x.pop("schema"), "schema"),
        ("schema_number", lambda x: x.__setitem__("schema", 1), "schema"),
        ("schema_other", lambda x: x.__setitem__("schema", "lidarcam.observations/9"), "schema"),
        ("boards_missing", lambda x: x.pop("boards"), "boards"),
        ("boards_dict", lambda x: x.__setitem__("boards", {"0": x["boards"][0]}), "boards"),
        ("boards_string", lambda x: x.__setitem__("boards", "many"), "boards"),
        ("board_string", lambda x: x["boards"].__setitem__(1, "board"), None),
        ("board_list", lambda x: x["boards"].__setitem__(1, [1, 2, 3]), None),
        ("board_null", lambda x: x["boards"].__setitem__(1, None), None),
        ("scan_missing", lambda x: x["boards"][1].pop("scan"), "scan"),
        ("outline_missing", lambda x: x["boards"][1].pop("outline"), "outline"),
        ("pose_missing", lambda x: x["boards"][1].pop("T_cam_board"), "T_cam_board"),
        ("pose_string", b1("T_cam_board", "identity"), "T_cam_board"),
        ("pose_string_matrix", b1("T_cam_board", [["1", "0", "0", "0"]] * 4), "T_cam_board"),
        ("pose_bool_matrix", lambda x: x["boards"][1]["T_cam_board"][3].__setitem__(3, True), "T_cam_board"),
        ("pose_3x3", lambda x: x["boards"][1].__setitem__("T_cam_board", [r[:3] for r in x["boards"][1]
                                                                          ["T_cam_board"][:3]]), "T_cam_board"),
        ("pose_reflection", lambda x: [r.__setitem__(0, -r[0]) for r in x["boards"][1]["T_cam_board"][:3]],
         "T_cam_board"),
        ("pose_not_rotation", lambda x: x["boards"][1]["T_cam_board"][0].__setitem__(0, 1.01), "T_cam_board"),
        ("pose_last_row", lambda x: x["boards"][1]["T_cam_board"][3].__setitem__(0, 0.5), "T_cam_board"),
        ("scan_bool", leaf("scan", True), "scan"),
        ("scan_false", leaf("scan", False), "scan"),
        ("scan_string_number", leaf("scan", "1.5"), "scan"),
        ("scan_null", leaf("scan", None), "scan"),
        ("scan_object", leaf("scan", {"x": 1}), "scan"),
        ("pose_translation_1e300", lambda x: x["boards"][1]["T_cam_board"][0].__setitem__(3, 1e300), "T_cam_board"),
        ("scan_point_1e300", lambda x: x["boards"][2]["scan"].__setitem__(0, [1e300, 1e300]), "scan"),
        ("scan_three_columns", lambda x: [p.append(0.0) for p in x["boards"][2]["scan"]], "scan"),
        ("scan_one_point", lambda x: x["boards"][2].__setitem__("scan", x["boards"][2]["scan"][:1]), "scan"),
        ("scan_empty", b1("scan", []), "scan"),
        ("scan_nested", lambda x: x["boards"][2].__setitem__("scan", [[p] for p in x["boards"][2]["scan"]]), "scan"),
        ("scan_flat", lambda x: x["boards"][2].__setitem__("scan", sum(x["boards"][2]["scan"], [])), "scan"),
        ("outline_bool", leaf("outline", True), "outline"),
        ("outline_two_vertices", lambda x: x["boards"][2].__setitem__("outline", x["boards"][2]["outline"][:2]),
         "outline"),
        ("outline_bowtie", lambda x: x["boards"][2].__setitem__("outline", [[0, 0], [1, 1], [1, 0], [0, 1]]),
         "outline"),
        ("outline_zero_area", lambda x: x["boards"][2].__setitem__("outline", [[0, 0], [1, 0], [2, 0]]), "outline"),
        ("meta_list", lambda x: x.__setitem__("meta", [1, 2]), "meta"),
        ("meta_string", lambda x: x.__setitem__("meta", "simulated"), "meta"),
        ("meta_number", lambda x: x.__setitem__("meta", 3), "meta"),
        ("truth_string", lambda x: x.__setitem__("ground_truth", "none"), "ground_truth.T_lidar_cam"),
        ("truth_bool", lambda x: x["ground_truth"]["T_lidar_cam"][0].__setitem__(0, True),
         "ground_truth.T_lidar_cam"),
        ("truth_not_rigid", lambda x: x["ground_truth"]["T_lidar_cam"][0].__setitem__(0, 2.0),
         "ground_truth.T_lidar_cam"),
    ]
    out = []
    for name, fn, field in spec:
        if name == "top_list":
            out.append(Case(name, "types", dump([d]), "refused"))
            out.append(Case("top_string", "types", dump("boards"), "refused"))
            out.append(Case("top_number", "types", b"42", "refused"))
            out.append(Case("top_null", "types", b"null", "refused"))
            continue
        out.append(Case(name, "types", _edit(d, fn), "refused", field))
    return out


def _round6(x):
    for b in x["boards"]:
        b["T_cam_board"] = [[round(v, 6) for v in r] for r in b["T_cam_board"]]
    x["ground_truth"]["T_lidar_cam"] = [[round(v, 6) for v in r] for r in x["ground_truth"]["T_lidar_cam"]]


def tolerance_cases(d: dict) -> list[Case]:
    return [
        Case("rotation_6_decimals", "tolerance", _edit(d, _round6), "correct"),
        Case("closed_outline", "tolerance", _edit(d, lambda x: [b["outline"].append(b["outline"][0])
                                                                for b in x["boards"]]), "correct"),
        Case("meta_null", "tolerance", _edit(d, lambda x: x.__setitem__("meta", None)), "correct"),
        Case("unknown_keys", "tolerance", _edit(d, lambda x: x.__setitem__("comment", "hi")), "correct"),
        Case("integer_coordinates", "tolerance", _edit(d, lambda x: x["boards"][0].__setitem__(
            "outline", [[0, 0], [1, 0], [1, 1], [0, 1]])), "correct"),
    ]


def limit_cases(d: dict) -> list[Case]:
    b0 = d["boards"][0]
    ring = [[0.5 + 0.5 * np.cos(a), 0.5 + 0.5 * np.sin(a)] for a in np.linspace(0, 2 * np.pi, 3000, endpoint=False)]
    ring65 = ring[:: 3000 // (MAX_OUTLINE_VERTICES + 1)][: MAX_OUTLINE_VERTICES + 1]
    return [
        Case("too_many_boards", "limits", _edit(d, lambda x: x.__setitem__("boards", [b0] * (MAX_BOARDS + 1))),
             "refused", "boards"),
        Case("huge_scan", "limits", _edit(d, lambda x: x["boards"][0].__setitem__(
            "scan", [[5.0, 0.0]] * (MAX_SCAN_POINTS + 1))), "refused", "scan"),
        Case("oversized_scan_200k", "limits", _edit(d, lambda x: x["boards"][0].__setitem__(
            "scan", [[5.0, 0.0]] * 200_000)), "refused", "scan"),
        Case("outline_3000_vertices", "limits", _edit(d, lambda x: x["boards"][0].__setitem__("outline", ring)),
             "refused", "outline"),
        Case("outline_65_vertices", "limits", _edit(d, lambda x: x["boards"][0].__setitem__("outline", ring65)),
             "refused", "outline"),
    ]


def copy_cases(d: dict, d3: dict, d94: dict) -> list[Case]:
    """Copies: a board whose 40 scan points are one point repeated (no line: that board is left out or refused by
    name), 94 boards with 6 of them listed twice (100 boards: the exhaustive methods must bound their memory), 3
    boards each listed twice (the verdict names the duplicates)."""
    def repeated(x):
        x["boards"][2]["scan"] = [x["boards"][2]["scan"][5]] * 40

    return [
        Case("scan_one_point_repeated", "limits", _edit(d, repeated), "correct"),
        Case("boards_100_six_listed_twice", "limits", _edit(d94, lambda x: x["boards"].extend(x["boards"][:6])),
             "correct", cause="duplicated"),
        Case("boards_3_each_listed_twice", "limits", _edit(d3, lambda x: x["boards"].extend(x["boards"][:])),
             "warned", cause="duplicated"),
    ]


def _scale_scan(x, i, s):
    x["boards"][i]["scan"] = [[s * p[0], s * p[1]] for p in x["boards"][i]["scan"]]


def _push_back(x, i, dr):
    pts = np.array(x["boards"][i]["scan"])
    r = np.linalg.norm(pts, axis=1, keepdims=True)
    x["boards"][i]["scan"] = (pts * (1 + dr / r)).tolist()


def physics_cases(d: dict, tag: str, rng) -> list[Case]:
    N = len(d["boards"])
    perm = rng.permutation(N)
    while np.any(perm == np.arange(N)):
        perm = rng.permutation(N)
    i, j = rng.choice(N, 2, replace=False)

    def swap(x):
        x["boards"][i]["scan"], x["boards"][j]["scan"] = x["boards"][j]["scan"], x["boards"][i]["scan"]

    def permute(x):
        scans = [b["scan"] for b in x["boards"]]
        for k, b in enumerate(x["boards"]):
            b["scan"] = scans[perm[k]]

    def shift(x):
        scans = [b["scan"] for b in x["boards"]]
        for k, b in enumerate(x["boards"]):
            b["scan"] = scans[(k + 1) % N]

    def mm_scans(x):
        for k in range(N):
            _scale_scan(x, k, 1000.0)

    def mm_poses(x):
        for b in x["boards"]:
            for r in b["T_cam_board"][:3]:
                r[3] *= 1000.0

    def mm_outline(x):
        for b in x["boards"]:
            b["outline"] = [[1000 * v for v in p] for p in b["outline"]]

    def mirror(x):
        for b in x["boards"]:
            b["scan"] = [[p[0], -p[1]] for p in b["scan"]][::-1]

    def behind(x):
        T = x["boards"][i]["T_cam_board"]
        for r in T[:3]:
            r[3] = -r[3]

    def at_zero(x):
        for r in x["boards"][i]["T_cam_board"][:3]:
            r[3] = 0.0

    def scaled(x):
        for b in x["boards"]:
            for r in b["T_cam_board"][:3]:
                r[3] *= 1.15

    def origin_point(x):
        x["boards"][i]["scan"].insert(len(x["boards"][i]["scan"]) // 2, [0.0, 0.0])

    return [
        Case(f"scan_2m_behind_{tag}", "physics", _edit(d, lambda x: _push_back(x, i, 2.0)), "flagged"),
        Case(f"two_scans_swapped_{tag}", "physics", _edit(d, swap), "flagged", cause="mispaired"),
        Case(f"scans_permuted_{tag}", "physics", _edit(d, permute), "flagged", cause="mispaired"),
        Case(f"scans_shifted_{tag}", "physics", _edit(d, shift), "flagged", cause="mispaired"),
        Case(f"scans_in_mm_{tag}", "physics", _edit(d, mm_scans), "flagged", cause="units"),
        Case(f"poses_in_mm_{tag}", "physics", _edit(d, mm_poses), "flagged", cause="units"),
        Case(f"outline_in_mm_{tag}", "physics", _edit(d, mm_outline), "flagged", cause="units"),
        Case(f"mirrored_lidar_{tag}", "physics", _edit(d, mirror), "warned", cause="mirrored"),
        Case(f"board_behind_camera_{tag}", "physics", _edit(d, behind), "flagged"),
        Case(f"board_at_zero_{tag}", "physics", _edit(d, at_zero), "flagged"),
        Case(f"poses_scaled_{tag}", "physics", _edit(d, scaled), "undetectable", cause="scale"),
        Case(f"point_at_origin_{tag}", "types", _edit(d, origin_point), "refused", "scan"),
    ]


def corpus(physics_seeds: int = 2, n_boards: int = 5, lidar_res_deg: float = 0.5) -> list[Case]:
    """The whole corpus: 80 file cases and 12 physics cases per seed (small problems, to keep the tests fast)."""
    d = base(6, seed=0)
    out = byte_cases(d) + type_cases(d) + tolerance_cases(d) + limit_cases(d)
    out += copy_cases(d, base(3, seed=3), base(94, seed=5, lidar_res_deg=0.5))
    rng = np.random.default_rng(11)
    for s in range(physics_seeds):
        out += physics_cases(base(n_boards, seed=1 + s, lidar_res_deg=lidar_res_deg), f"s{s}", rng)
    return out
