"""One source for the contract: :mod:`dgan.contract` is what the engine exports (``dgan._dgan.CONTRACT``), and no
module of the package, training, benchmarks or tests types one of its lists again."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import numpy as np

import dgan
from dgan import _dgan, contract

ROOT = Path(__file__).resolve().parents[2]
#: The engine's lists, each of which nothing may copy as a literal.
OWNED: dict[str, tuple[str, ...]] = {
    "classes": contract.CLASSES,
    "map kinds": contract.MAP_ELEMENT_KINDS,
    "state features": contract.STATE_FEATURES,
    "edge features": contract.EDGE_FEATURES,
    "edge-list inputs": contract.EDGE_LIST_INPUTS,
    "padded inputs": contract.PADDED_INPUTS,
    "outputs": contract.OUTPUTS,
}


def test_the_python_contract_is_the_engines() -> None:
    c = _dgan.CONTRACT
    assert contract.VERSION == c["version"] == _dgan.CONTRACT_VERSION
    assert contract.CLASSES == tuple(c["classes"]) == dgan.CLASSES == ("vehicle", "cyclist", "pedestrian")
    assert [k.name for k in contract.MAP_KINDS] == [k["name"] for k in c["map_kinds"]]
    assert contract.MAP_KINDS[0].name == "bike_lane"  # drawing order: regions first, centre lines last
    assert contract.MAP_KINDS[-1].name == "lane_centerline"
    assert all((k.width_m is None) == k.polygon for k in contract.MAP_KINDS)
    assert contract.map_kind("obstacle").colour == (255, 105, 180)
    assert contract.state_width(("vehicle", "pedestrian")) == len(contract.STATE_FEATURES) + 2
    assert contract.CACHE_KEY.endswith(f"raster{contract.RASTER_VERSION}-preprocess{contract.PREPROCESS_VERSION}")


def test_the_inputs_are_those_preprocessing_gives() -> None:
    zara1 = dgan.Predictor("zara1")
    frame = dgan.Frame(np.cumsum(np.ones((3, 8, 2)) * 0.3, axis=1) + np.arange(3)[:, None, None])
    spec = zara1.spec
    got = dgan.preprocess(frame, spec)
    layout = contract.PADDED_INPUTS if spec.graph == "padded" else contract.EDGE_LIST_INPUTS
    wanted = [n for n in layout if n in got]
    optional = spec.map is not None and spec.map.optional
    scene = spec.map.scene if spec.map is not None else None
    per_call = scene is not None and not scene.tile_px  # contract 12's grids; contract 13 reads kept tiles
    grids = ("map_grid", "map_slot")
    assert wanted == [n for n in layout if (n != "map_present" or optional) and (n not in grids or per_call)]
    assert all(k in got for k in ("map_rows", "map_index", "map_weight")) == (scene is not None and not per_call)
    assert got["state"].shape[1] == spec.state_dim == contract.state_width(spec.classes)
    key = "neighbor_features" if spec.graph == "padded" else "edge_features"
    assert got[key].shape[-1] == len(contract.EDGE_FEATURES)


def literal_copies(path: Path) -> list[str]:
    """Tuple, list or set literals of three or more distinct strings that all belong to one of the engine's lists
    (or all of a shorter one), and a state width typed as a number."""
    text = path.read_text()
    lines = text.splitlines()
    found = []
    for node in ast.walk(ast.parse(text)):
        # Lists of names, not mappings keyed by them (a class's colour in a picture is the picture's own knowledge).
        if not isinstance(node, (ast.Tuple, ast.List, ast.Set)):
            continue
        items = [e.value for e in node.elts if isinstance(e, ast.Constant) and isinstance(e.value, str)]
        if len(items) != len(node.elts) or len(items) < 2 or len(set(items)) != len(items):
            continue  # per-agent data (a class for each agent, repeated) is not a copy of a list
        if "# not a contract copy" in lines[node.lineno - 1]:
            continue  # a source's own vocabulary, or what one map is expected to hold
        for what, owned in OWNED.items():
            if set(items) <= set(owned) and (len(items) >= 3 or set(items) == set(owned)):
                found.append(f"{path.relative_to(ROOT)}:{node.lineno}: a copy of the engine's {what} {items}")
    for i, line in enumerate(lines, 1):
        if re.search(r"\b7 \+ len\(", line):
            found.append(f"{path.relative_to(ROOT)}:{i}: the state width typed as 7 + len(...)")
    return found


def test_no_module_types_the_engines_lists_again() -> None:
    here = Path(__file__).resolve()
    files = [p for d in ("python", "training", "tests", "benches") for p in (ROOT / d).rglob("*.py") if p != here]
    copies = [c for p in sorted(files) for c in literal_copies(p)]
    assert not copies, "derive these from dgan.contract:\n" + "\n".join(copies)


def test_the_check_finds_a_new_copy(tmp_path: Path) -> None:
    bad = ROOT / "tests" / "python" / "_copy_probe.py"
    try:
        bad.write_text('KINDS = ("crosswalk", "road_edge", "obstacle")\nWIDTH = 7 + len(classes)\n')
        assert len(literal_copies(bad)) == 2
    finally:
        bad.unlink()


def test_mirroring_a_scene_negates_the_mirrored_columns_and_nothing_else() -> None:
    """The engine's mirror signs (``STATE_MIRRORED``, ``EDGE_MIRRORED``) are what preprocessing does: the inputs of a
    scene mirrored y → −y in the world are those of the scene with these columns (and every y) negated."""
    t = np.arange(8)[:, None] * 0.4
    positions = np.stack(
        [np.hstack([1.3 * t, 0.2 * t**2]), np.hstack([4 - 0.8 * t, 1 + 0.5 * t]), np.hstack([2 + t, -1 - 0.1 * t])]
    )
    spec = dgan.InputSpec(dt_s=0.4, t_obs=8, t_f=12, classes=("vehicle", "pedestrian"), heading="motion")
    classes = ["vehicle", "pedestrian", "vehicle"]
    a = dgan.preprocess(dgan.Frame(positions, classes=classes), spec)
    b = dgan.preprocess(dgan.Frame(positions * [1.0, -1.0], classes=classes), spec)
    np.testing.assert_allclose(b["trajectory"], a["trajectory"] * [1.0, -1.0], atol=1e-5)
    state_sign = np.array([-1.0 if c in contract.STATE_MIRRORED else 1.0 for c in contract.STATE_FEATURES])
    n = len(contract.STATE_FEATURES)
    np.testing.assert_allclose(b["state"][:, :n], a["state"][:, :n] * state_sign, atol=1e-5)
    edge_sign = np.array([-1.0 if c in contract.EDGE_MIRRORED else 1.0 for c in contract.EDGE_FEATURES])
    np.testing.assert_array_equal(a["edge_index"], b["edge_index"])
    np.testing.assert_allclose(b["edge_features"], a["edge_features"] * edge_sign, atol=1e-5)
    assert np.abs(a["state"][:, :n] * (state_sign < 0)).max() > 0.01  # the mirrored columns are not all zero
