"""Growth in closed containers, stopped at a target fraction (issue 41, item 5):
``peclet pack --protocol grow --container box:AxBxC|column:N --target-phi X`` and
``peclet.packing.experiments.grow`` with ``GrowSpec.container``."""
import json
import math

import numpy as np
import pytest

from peclet.cli import main
from peclet.packing.experiments.grow import GrowSpec, grow
from peclet.packing.experiments.grow_containers import COLUMN_TAPER


def _inside(P, res, r):
    """How far (D) the spheres of radius ``r`` at ``P`` reach past the final container's
    walls (<= 0: every sphere inside)."""
    c = res["container"]
    if c["kind"] == "box":
        return float((np.abs(P) + r - 0.5 * np.asarray(c["size"])).max())
    D_t, H = c["size"]
    radial = np.hypot(P[:, 0], P[:, 2]) + r - (0.5 * D_t + COLUMN_TAPER)
    axial = np.abs(P[:, 1]) + r - 0.5 * H
    return float(max(radial.max(), axial.max()))


def test_spheres_grown_in_a_closed_box_from_the_command_line(tmp_path, capsys):
    out = tmp_path / "grown"
    rc = main(["pack", "--protocol", "grow", "--element", "sphere", "--count", "30",
               "--container", "box:4x4x4", "--target-phi", "0.4", "--mu", "0",
               "--restitution", "0.5", "--seed", "2", "--out", str(out), "--quiet"])
    assert rc == 0
    assert "target phi 0.4 reached" in capsys.readouterr().out
    res = json.loads((out / "results.json").read_text())
    assert res["target_reached"] and not res["jammed"]
    # the start fraction 30 (pi / 6) / 64 = 0.245; the box shrank exactly to the target
    assert res["phi"] == pytest.approx(0.4, rel=1e-12)
    side = res["container"]["size"][0]
    assert side == pytest.approx((30 * math.pi / 6 / 0.4) ** (1 / 3), rel=1e-12)
    gap = res["spec"]["gap"]
    assert res["max_overlap_pairs"] <= gap and res["max_overlap_walls"] <= gap
    with np.load(out / "grown.npz") as z:
        P = z["positions"]
        assert str(z["container_kind"]) == "box" and "box" not in z.files
        assert np.allclose(z["container_size"], [side] * 3, rtol=1e-12)
    assert len(P) == 30 and _inside(P, res, 0.5) <= gap
    d = np.linalg.norm(P[:, None] - P[None], axis=-1) + 10.0 * np.eye(30)
    assert d.min() >= 1.0 - gap
    assert res["wall_contacts"] > 0


def test_spheres_grown_in_a_closed_column():
    res = grow(GrowSpec(count=30, container="column:4", target_phi=0.4, seed=2),
               progress=False)
    assert res["target_reached"]
    assert res["phi"] == pytest.approx(0.4, rel=1e-12)
    P = res["sim"].get_positions()
    gap = res["spec"]["gap"]
    assert res["max_overlap"] <= gap and _inside(P, res, 0.5) <= gap
    # the column kept its aspect: diameter and height shrank by the same factor
    c = res["container"]
    assert c["size"][0] / c["start_size"][0] == pytest.approx(c["scale"], rel=1e-12)
    assert c["size"][1] / c["start_size"][1] == pytest.approx(c["scale"], rel=1e-12)


def test_target_phi_is_refused_with_rain(tmp_path, capsys):
    rc = main(["pack", "--protocol", "rain", "--target-phi", "0.4", "--out",
               str(tmp_path / "r"), "--quiet"])
    assert rc == 2
    assert "--target-phi must be given only with --protocol grow" in capsys.readouterr().err
