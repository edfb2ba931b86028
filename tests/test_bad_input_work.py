"""In-range values that imply absurd work are refused before the run starts, with the estimate
(issue 45, class 2): a drum or a stirrer turning at 1e-12 needs ~1e12 steps a revolution."""
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
