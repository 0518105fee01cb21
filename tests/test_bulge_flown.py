"""The curtain bulge flown by the simulator (``walls.model``): the world's kernel follows the law the gap effect
``wall_bulge`` fits (:func:`finkensim.gap.model.bulge.bulge_displacement`, its NumPy reference), the sense step sees
the bulged plates in the compiled loop and the reference path alike, and bad keys are named errors."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from finkensim.arena import HingeParams, bulge_cutoff, bulge_step_env
from finkensim.config import ConfigError, load_config
from finkensim.gap.attribute import effects as fx
from finkensim.gap.model.bulge import bulge_displacement
from finkensim.gap.model.params import ModelParams

HP = HingeParams(False, 1.0, 0.5, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1)


@settings(max_examples=60, deadline=None)
@given(amplitude=st.floats(-0.1, 0.5), reach=st.floats(0.05, 1.5), response=st.floats(0.0, 3.0),
       shape=st.floats(1.0, 12.0), T=st.integers(1, 30), seed=st.integers(0, 2**31),
       hinge=st.one_of(st.just(0.0), st.just(1.0), st.floats(0.0, 1.0)))
def test_bulge_kernel_matches_the_diagnosis_law(amplitude, reach, response, shape, T, seed, hinge):
    """One law (arena.bulge_law): the world's compiled step and the diagnosis's NumPy displacement, any hinge weight."""
    d = np.random.default_rng(seed).uniform(0.0, 2.0, size=(T, 5))
    dt = 0.02
    hp = HP._replace(bulge_amplitude=amplitude, bulge_reach=reach, bulge_shape=shape, bulge_response=response,
                     bulge_cutoff=bulge_cutoff(reach, shape), bulge_hinge=hinge)
    x = np.zeros(5)
    got = np.empty((T, 5))
    for k in range(T):
        bulge_step_env(x, d[k], hp, dt, k == 0)
        got[k] = x
    want = bulge_displacement(d, amplitude, reach, response, np.arange(T) * dt, shape, hinge)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-15)


def test_cutoff_bounds_the_target():
    for reach, shape in ((0.05, 1.0), (1.5, 12.0), (0.3, 2.0)):
        assert np.exp(-(bulge_cutoff(reach, shape) / reach) ** shape) <= 1.0001e-300


@pytest.mark.parametrize("key,bad", [("walls.model", "bulgy"), ("walls.bulge_reach", 0.0),
                                     ("walls.bulge_amplitude", 2.0), ("walls.bulge_response", -1.0),
                                     ("walls.bulge_hinge", 1.5), ("walls.bulge_hinge", -0.1)])
def test_bad_bulge_keys_are_named_errors(key, bad):
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        load_config().replace({key: bad})


@pytest.mark.parametrize("bending", [True, False])
def test_wall_bulge_calibrates_the_wall_model(bending):
    cfg = load_config().replace({"walls.bending": bending})
    v = {"amplitude": 0.12, "reach": 0.4, "response": 0.3, "shape": 4.0}
    upd = fx.REGISTRY["wall_bulge"].calibrate(v, cfg)
    assert upd["walls.model"] == ("hinge+bulge" if bending else "bulge")
    p = ModelParams.from_config(cfg.replace(upd))
    assert (p.wall_gain, p.bulge_amplitude, p.bulge_reach, p.bulge_response, p.bulge_shape) == (
        1.0 if bending else 0.0, 0.12, 0.4, 0.3, 4.0)


SMALL = {"copters.n": 4, "behaviour.kind": "random_walk", "simulation.dt": 0.02, "arena.width": 1.5,
         "arena.length": 1.5, "walls.model": "bulge", "walls.bulge_amplitude": 0.2, "walls.bulge_reach": 0.3,
         "walls.bulge_response": 0.2, "walls.bulge_hinge": 0.5}


@pytest.fixture(scope="module")
def bulged():
    from finkensim.swarm import SwarmSim

    sim = SwarmSim(load_config().replace(SMALL))
    s0 = sim.init(n_envs=2, seed=3)
    final, rec = sim.rollout(s0, 30, record=("pose", "sonar", "sonar_ideal", "theta"))
    _, rec_py = sim.rollout(s0, 30, record=("sonar", "sonar_ideal"), python=True)
    rigid = SwarmSim(load_config().replace({**SMALL, "walls.bulge_amplitude": 0.0}))
    _, rec_rigid = rigid.rollout(rigid.init(n_envs=2, seed=3), 30, record=("sonar_ideal",))
    return sim, final, rec, rec_py, rec_rigid


def test_the_world_follows_the_bulge_law(bulged):
    """The final state's bulge is the diagnosis's displacement of the flown positions (the plates' distances to the
    nearest copter body, as the replay computes them)."""
    from finkensim.kernels.geometry import nearest_body_distance_env

    sim, final, rec, _, _ = bulged
    geo, hp, r = sim.world.geometry, sim.world.hinge_params, sim.world.copter_params.radius
    assert not hp.bending and (rec.theta == 0).all()  # "bulge" alone: the hinge does not move
    assert hp.bulge_hinge == 0.5  # walls.bulge_hinge flown: the hinge law blended into the bulge's target
    pos = np.concatenate([rec.pose[..., :2], final.world.pos[None]], axis=0)
    T, B = pos.shape[:2]
    for b in range(B):
        d = np.empty((T, geo.seg_a.shape[0]))
        for k in range(T):
            nearest_body_distance_env(geo.seg_a, geo.seg_b, np.ascontiguousarray(pos[k, b]), r, d[k])
        want = bulge_displacement(d, hp.bulge_amplitude, hp.bulge_reach, hp.bulge_response, np.arange(T) * 0.02,
                                  hp.bulge_shape, hp.bulge_hinge)
        np.testing.assert_allclose(final.world.bulge[b], want[-1], rtol=1e-9, atol=1e-12)


def test_the_sonars_see_the_bulge(bulged):
    _, final, rec, rec_py, rec_rigid = bulged
    np.testing.assert_array_equal(rec.sonar, rec_py.sonar)
    np.testing.assert_array_equal(rec.sonar_ideal, rec_py.sonar_ideal)
    # the curtain bulges toward the arena: no echo reads longer, some shorter
    assert (rec.sonar_ideal <= rec_rigid.sonar_ideal + 1e-12).all()
    assert (rec.sonar_ideal < rec_rigid.sonar_ideal - 0.01).any()
    assert final.world.bulge.shape == (2, 4 * 16)
