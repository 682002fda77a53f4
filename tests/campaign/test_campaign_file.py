"""The campaign file, per-trial seeds and parameter draws, the Wilson interval."""
from __future__ import annotations

import math

import pytest

from spacearm.base.config.errors import ConfigError
from spacearm.base.paths import CONFIGS
from spacearm.offline.campaign.report import wilson_interval
from spacearm.offline.campaign.schema import ParameterRange, load_campaign, trial_seed


def test_every_shipped_campaign_file_loads():
    files = sorted((CONFIGS / "campaigns").glob("*.toml"))
    assert len(files) >= 5
    for f in files:
        assert load_campaign(f).spec.campaign.trials >= 1


def test_trial_seed_depends_on_campaign_seed_and_index_only(ekf_campaign):
    small = load_campaign(ekf_campaign(seed=3, trials=4, name="a.toml"))
    large = load_campaign(ekf_campaign(seed=3, trials=400, name="b.toml"))
    assert [small.trial_seed(i) for i in range(4)] == [large.trial_seed(i) for i in range(4)]
    assert small.draw(small.trial_seed(2)) == large.draw(large.trial_seed(2))
    assert len({trial_seed(3, i) for i in range(1000)}) == 1000
    assert trial_seed(3, 0) != trial_seed(4, 0)


@pytest.mark.parametrize("dist", ["uniform", "disc_radius", "log_uniform"])
def test_draws_stay_in_range(dist):
    import numpy as np
    r = ParameterRange(low=0.001, high=0.008, distribution=dist)
    rng = np.random.default_rng(0)
    values = [r.draw(rng) for _ in range(2000)]
    assert min(values) >= 0.001 and max(values) <= 0.008
    if dist == "disc_radius":      # uniform over the annulus: more mass at large radii
        assert np.median(values) > 0.0045


@pytest.mark.parametrize("text, key", [
    ('[campaign]\nname="x"\nkind="nope"\nseed=1\ntrials=2\n', "campaign.kind"),
    ('[campaign]\nname="x"\nkind="insertion"\nseed=1\ntrials=0\n', "campaign.trials"),
    ('[campaign]\nname="x"\nkind="insertion"\nseed=1\ntrials=2\n[parameters.speed]\nlow=0\nhigh=1\n',
     "parameters.speed"),
    ('[campaign]\nname="x"\nkind="insertion"\nseed=1\ntrials=2\n[parameters.tilt_angle]\nlow=1\nhigh=0\n',
     "parameters.tilt_angle"),
    ('[campaign]\nname="x"\nkind="checkout"\nseed=1\ntrials=2\n[options]\nwarp=9\n', "options.warp"),
    ('[campaign]\nname="x"\nkind="insertion"\nseed=1\ntrials=2\n[options]\nmax_cycles="many"\n',
     "options.max_cycles"),
])
def test_bad_campaign_file_names_the_key(tmp_path, text, key):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as err:
        load_campaign(path)
    assert str(path) in str(err.value) and key in str(err.value)


def test_wilson_interval_known_values():
    lo, hi = wilson_interval(0, 10)
    assert lo == 0.0 and hi == pytest.approx(0.2775, abs=1e-4)
    lo, hi = wilson_interval(95, 100)
    assert lo == pytest.approx(0.8882, abs=1e-3) and hi == pytest.approx(0.9785, abs=1e-3)
    lo, hi = wilson_interval(50, 100)
    assert lo + hi == pytest.approx(1.0) and lo < 0.5 < hi
    assert wilson_interval(0, 0) == (0.0, 1.0)
    assert not math.isnan(wilson_interval(10, 10)[0])


LEVELS = ('[campaign]\nname="x"\nkind="calibration_ekf"\nseed=1\ntrials=9\n'
          '[levels.sigma_position]\nvalues=[1e-5, 3e-4]\n[levels.sigma_rotation]\nvalues=[0.1, 0.2, 0.3]\n')


def test_levels_take_their_full_cross_in_turn_and_the_draws_stay_seeded(tmp_path):
    path = tmp_path / "levels.toml"
    path.write_text(LEVELS)
    c = load_campaign(path)
    cells = [(c.parameters(i)["sigma_position"], c.parameters(i)["sigma_rotation"]) for i in range(9)]
    assert cells[:6] == [(1e-5, 0.1), (1e-5, 0.2), (1e-5, 0.3), (3e-4, 0.1), (3e-4, 0.2), (3e-4, 0.3)]
    assert cells[6:] == cells[:3]                      # the cross starts again
    path.write_text(LEVELS + '[parameters.configurations]\nlow=20\nhigh=60\n')
    c = load_campaign(path)
    assert c.parameters(4)["configurations"] == c.draw(c.trial_seed(4))["configurations"]
    assert c.parameters(4)["sigma_rotation"] == 0.2


@pytest.mark.parametrize("extra, key", [
    ('[levels.speed]\nvalues=[1.0]\n', "levels.speed"),
    ('[levels.configurations]\nvalues=[]\n', "levels.configurations"),
    ('[levels.configurations]\nvalues=[10]\n[parameters.configurations]\nlow=1\nhigh=2\n', "configurations"),
])
def test_bad_levels_name_the_key(tmp_path, extra, key):
    path = tmp_path / "bad.toml"
    path.write_text('[campaign]\nname="x"\nkind="calibration_ekf"\nseed=1\ntrials=2\n' + extra)
    with pytest.raises(ConfigError) as err:
        load_campaign(path)
    assert key in str(err.value)


def test_a_campaign_written_by_a_program_reads_back_as_written():
    from spacearm.offline.campaign.schema import campaign_from_text, campaign_text
    text = campaign_text("study", "calibration_ekf", 3, 8, levels={"configurations": [10, 20]},
                         options={"methods": ["lse", "lm"], "per_posture": True, "validation_seed": 7})
    c = campaign_from_text(text)
    assert (c.name, c.kind, c.spec.campaign.seed, c.spec.campaign.trials) == ("study", "calibration_ekf", 3, 8)
    assert [c.parameters(i)["configurations"] for i in range(3)] == [10.0, 20.0, 10.0]
    assert c.spec.options == {"methods": ["lse", "lm"], "per_posture": True, "validation_seed": 7}
