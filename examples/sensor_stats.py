"""Sonar and IMU numbers quoted in docs/user-guide/sensors.md, reproducible with one command:

    .venv/bin/python examples/sensor_stats.py        # ≈ 20 s (includes a 60 s demo flight)

Prints, each computed here from the package's own kernels and config defaults:

1. the sonar echo error of every ``sonar.error`` model at a true distance of 1.5 m: analytic mean
   and std of (reading − true) next to a Monte-Carlo estimate from the down-sonar kernel (which
   applies the same error model without cross-talk), for the default σ = 0.05 m and the original
   script's σ = 1 m; then the report's seed rule (spike at d/2 plus shifted Rayleigh);
2. geometric cross-talk on a constructed geometry: two copters 1 m apart facing each other, in the
   same firing slot and in different slots;
3. how often cross-talk shortens a reading in the default 60 s demo flight (the one
   ``finkensim run --out out/demo`` writes), per firing schedule;
4. the IMU's per-sample noise at the default dt = 0.05 s and the bias random walk after 60 s,
   analytic and Monte Carlo.
"""
from __future__ import annotations

import math

import numpy as np

from finkensim.config import Config
from finkensim.scenario import load_scenario, simulate_flight
from finkensim.sensors.imu import ImuModel, ImuState, imu_step
from finkensim.sensors.sonar import SonarModel, down_readings, rayleigh_std, sonar_readings
from finkensim.world import World

N_MC = 200_000
TRUE = 1.5  # m


def sonar_error_models() -> None:
    print(f"1. sonar echo error at true distance {TRUE} m (reading − true, m), {N_MC} draws, no clamp active")
    k_s = math.sqrt((4 - math.pi) / 2)
    k_m = math.sqrt(math.pi / 2)
    print(f"   Rayleigh(σ): mean {k_m:.4f}σ, std s = sqrt((4 − π)/2)σ = {k_s:.4f}σ, so E[R − s] = {k_m - k_s:.4f}σ")
    print(f"   {'model':<26} {'σ (m)':>6} {'analytic mean ± std':>22} {'Monte Carlo mean ± std':>24}")
    pos = np.zeros((1, N_MC, 2))
    for error, sign, sigma in (("rayleigh", -1.0, 0.05), ("rayleigh", 1.0, 0.05), ("seed", 1.0, 0.05),
                               ("gaussian", 1.0, 0.05), ("seed", 1.0, 1.0)):
        cfg = Config().replace({"sonar.error": error, "sonar.rayleigh_sign": sign, "sonar.sigma": sigma,
                                "sonar.min_range": 0.0, "sonar.max_range": 50.0})
        sp = SonarModel.from_config(cfg)
        y = down_readings(pos, sp, seed=3, env_ids=[0], step=0, altitude=TRUE)[0] - TRUE
        if error == "gaussian":
            m, s = 0.0, sigma
        else:
            m, s = (sign if error == "rayleigh" else 1.0) * (k_m - k_s) * sigma, k_s * sigma
        name = f"{error} (sign {sign:+.0f})" if error == "rayleigh" else error
        print(f"   {name:<26} {sigma:6.2f} {m:+10.4f} ± {s:.4f}      {y.mean():+10.4f} ± {y.std():.4f}")
    print(f"   the original script's σ = 1 m: s = {rayleigh_std(1.0):.3f} m; its replacement reading R − s is "
          "below the 0.2 m clamp (reads 0.2 m) with probability P(R < 0.2 + s) = "
          f"{1 - math.exp(-((0.2 + rayleigh_std(1.0)) ** 2) / 2):.3f}")


def seed_rule() -> None:
    print()
    d = 1.6
    print(f"1b. the report's seed rule (profile = 'seed': error 'seed', constant cross-talk 0.68), front sonar "
          f"{d} m from the east net, {N_MC} environments")
    cfg = Config(profile="seed").replace({"copters.n": 1})
    world = World(cfg)
    sp = SonarModel.from_config(cfg)
    pos = np.tile([[[world.arena.width - d, 2.0]]], (N_MC, 1, 1))
    theta = np.zeros((N_MC, world.arena.n_plates))
    y = sonar_readings(pos, np.zeros((N_MC, 1)), theta, world.arena, sp, 4, np.arange(N_MC), 0)[:, 0, 0]
    half = np.isclose(y, d / 2)
    rest = y[~half]
    s = rayleigh_std(cfg.sonar.sigma)
    print(f"   share reading exactly d/2 = {d / 2} m: {half.mean():.4f} (analytic {cfg.sonar.crosstalk_probability}); "
          f"others: mean − d {rest.mean() - d:+.4f} m, std {rest.std():.4f} m "
          f"(analytic {0.5982 * cfg.sonar.sigma:+.4f}, {s:.4f})")


def crosstalk_geometry() -> None:
    print()
    print("2. geometric cross-talk, copter 0 at (1, 2) m heading +x, copter 1 at (2, 2) m heading −x "
          "(1 m apart, facing), radius 0.15 m, no echo error")
    pos = np.array([[[1.0, 2.0], [2.0, 2.0]]])
    yaw = np.array([[0.0, math.pi]])
    for schedule, n_slots in (("simultaneous", 1), ("round_robin", 2)):
        cfg = Config().replace({"copters.n": 2, "sonar.error": "none", "sonar.schedule": schedule,
                                "sonar.n_slots": n_slots, "sonar.crosstalk_jitter": 0.0})
        world = World(cfg)
        sp = SonarModel.from_config(cfg)
        theta = np.zeros((1, world.arena.n_plates))
        out, ideal, _, _ = sonar_readings(pos, yaw, theta, world.arena, sp, 0, [0], 0, return_ideal=True)
        print(f"   schedule {schedule:<12} (slots {n_slots}): front sonars read {out[0, 0, 0]:.3f} m and "
              f"{out[0, 1, 0]:.3f} m; ideal echo off the other body {ideal[0, 0, 0]:.3f} m (1 m − radius)")


def crosstalk_rate() -> None:
    print()
    print("3. cross-talk in the default 60 s flight (seed 0, 6 copters): share of horizontal readings more than "
          "max(0.1 m, 5σ) = 0.25 m shorter than the ideal echo")
    base = load_scenario()
    for schedule in ("round_robin", "random_offset", "simultaneous"):
        cfg = base.replace({"sonar.schedule": schedule})
        slots = "1 slot" if schedule == "simultaneous" else f"{cfg.sonar.n_slots} slots"
        log, _, _ = simulate_flight(cfg, ideal=True)
        u = log.ultrasonic
        ideal = np.clip(log.extras["ultrasonic_ideal"], 0.2, 3.0)
        ev = u < ideal - 0.25
        per_copter = ev.mean(axis=(0, 2))
        print(f"   schedule {schedule:<13} ({slots}): {100 * ev.mean():5.1f} % of readings; per copter "
              + ", ".join(f"{100 * p:.0f}" for p in per_copter) + " %")
    print("   (round_robin: copters n and n + 4 share a slot; 45° cones on four sides cover all directions, "
          "so a slot-mate within 6 m is heard by one sonar nearly all the time)")


def imu_numbers() -> None:
    print()
    cfg = Config()
    dt = cfg.simulation.dt
    imu = cfg.imu
    p = ImuModel.from_config(imu, dt)
    print(f"4. IMU at dt = {dt} s (defaults: acc {imu.acc_noise_density} m/s²/√Hz, walk {imu.acc_bias_walk} m/s³/√Hz; "
          f"gyro {imu.gyro_noise_density} rad/s/√Hz, walk {imu.gyro_bias_walk} rad/s²/√Hz)")
    print(f"   MPU-6000 datasheet: 400 µg/√Hz = {400e-6 * 9.80665:.5f} m/s²/√Hz; 0.005 °/s/√Hz = "
          f"{math.radians(0.005):.2e} rad/s/√Hz")
    print(f"   white noise per sample: acc σ/√dt = {p.acc_sigma:.4f} m/s², gyro {p.gyro_sigma:.2e} rad/s")
    T = 60.0
    k = int(round(T / dt))
    n = 4000
    state = ImuState.zeros(1, n)
    zeros = np.zeros((1, n, 2))
    z1 = np.zeros((1, n))
    for step in range(k):
        imu_step(zeros, z1, z1, state, p, seed=5, env_ids=[0], step=step)
    b = state.bias[0]
    print(f"   bias after {T:g} s ({k} steps): std analytic sqrt(k·dt)·walk = acc {math.sqrt(k * dt) * imu.acc_bias_walk:.5f} "
          f"m/s², gyro {math.sqrt(k * dt) * imu.gyro_bias_walk:.2e} rad/s; Monte Carlo ({n} copters) acc "
          f"{b[:, :2].std():.5f} m/s², gyro {b[:, 2].std():.2e} rad/s")


if __name__ == "__main__":
    sonar_error_models()
    seed_rule()
    crosstalk_geometry()
    crosstalk_rate()
    imu_numbers()
