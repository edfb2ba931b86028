"""In-range values that imply absurd work are refused before the run starts, with the estimate
(issue 45, class 2): a drum or a stirrer turning at 1e-12 needs ~1e12 steps a revolution, a
flow lattice at D/64 of a wide pack hundreds of GiB, a 1e-9 wall a probe lattice past 1024^3."""
import pytest

from peclet.cli import main
from peclet.core.validation import PecletArgumentError
from peclet.packing.experiments import series


@pytest.mark.parametrize("argv,flag", [
    (["drum", "--froude", "1e-12"], "--froude"),
    (["drum", "--rpm", "1e-9"], "--rpm"),
    (["stir", "--omega", "1e-12"], "--omega"),
])
def test_a_turn_too_slow_to_finish_is_refused_with_its_estimate(tmp_path, capsys, argv, flag):
    out = tmp_path / "out"
    assert main(argv + ["--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith(f"peclet {argv[0]}: error: {flag}")
    assert "days on one core" in err and "steps of" in err and "days at" in err
    assert not out.exists()


def test_the_api_refuses_it_too_and_a_normal_speed_passes():
    from peclet.packing.experiments.drum import Drum, DrumSpec

    with pytest.raises(PecletArgumentError, match="froude must be a value whose run finishes"):
        Drum(DrumSpec(froude=1e-12).checked()).check_room()
    Drum(DrumSpec(froude=0.01).checked()).check_room()      # the documented default range


def test_the_estimate_is_steps_times_grains_times_the_grain_step_cost():
    limit = series.MAX_RUN_SECONDS / series.GRAIN_STEP_SECONDS      # grain-steps allowed
    ok = [series.Phase("a", 1.0, int(limit // 100))]
    series.check_work(ok, 100, "x", 1)
    with pytest.raises(PecletArgumentError, match="x must be"):
        series.check_work(ok + [series.Phase("b", 1.0, 1)], 100, "x", 1)


def _wide_pack(tmp_path):
    # 12 spheres in a 40 x 40 D periodic box: a flow lattice at D/64 would hold 2560 x 90 x
    # 2560 = 5.9e8 cells, about 280 GiB
    import numpy as np

    from peclet.core import geom
    from peclet.packing.bed.freeze import Pack, save_pack
    b = geom.SceneBuilder()
    root = b.add_leaf("sphere", [0.5])
    ni, nr, _, _ = b.encode()
    pos = np.array([[0.5 + 3 * i, 0.5 + (i % 3) * 0.7, 0.5 + 2 * i] for i in range(12)])
    pk = Pack(positions=pos, quaternions=np.tile([0.0, 0.0, 0.0, 1.0], (12, 1)),
              box=np.array([40.0, 40.0]), ring_volume=np.pi / 6, node_ints=ni,
              node_reals=nr, home_root=root, bounding_radius=0.5, shell=np.zeros((0, 3)),
              mass=np.nan, inv_inertia=np.full(3, np.nan))
    path = tmp_path / "pack.npz"
    save_pack(str(path), pk)
    return str(path)


def test_a_flow_lattice_beyond_the_memory_is_refused_with_its_estimate(tmp_path, capsys):
    import time

    from peclet.core.machine import physical_memory
    from peclet.flow.permeability import permeability
    if physical_memory() is None:
        pytest.skip("this OS does not tell its physical memory")
    pack = _wide_pack(tmp_path)
    t0 = time.perf_counter()
    with pytest.raises(PecletArgumentError, match=r"resolution must be a value whose job fits"
                       r".*2560 x 90 x 2560 lattice .*GiB"):
        permeability(pack, resolution=64, window=(0.5, 1.9))
    assert time.perf_counter() - t0 < 2.0          # refused before any work
    out = tmp_path / "flow"
    assert main(["flow", pack, "--resolutions", "8,64", "--window", "0.5,1.9", "--out",
                 str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("peclet flow: error: --resolutions")
    assert "D/64" in err and "GiB" in err and "cells" in err
    assert not out.exists()                        # the D/8 run did not start either


@pytest.mark.parametrize("thickness", ["0.0015", "0.002"])
def test_a_wall_too_thin_for_the_probe_lattice_is_refused(tmp_path, capsys, thickness):
    # the thin-wall rule used to cap the lattice at 1024^3 (about 24 GiB) and still miss
    # the wall's far face; now it is refused, naming the element and the thinnest wall (a
    # 1e-9 wall is refused before that: element lengths stay within 1000 of D, test_bad_input_extreme)
    out = tmp_path / "bed"
    assert main(["pack", "--element", f"raschig_ring:thickness={thickness}", "--count", "20",
                 "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert err.startswith("peclet pack: error: --element must be walls at least 0.00219 D")
    assert f"thinnest wall {float(thickness):.3g} D" in err
    assert not out.exists()
    from peclet.packing.bed.api import element_model, resolve_element
    with pytest.raises(PecletArgumentError, match="raschig_ring parameters must be walls"):
        element_model(resolve_element(f"raschig_ring:thickness={thickness}"))
