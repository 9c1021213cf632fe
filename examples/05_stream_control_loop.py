"""Step 5 - run the model online inside a fixed-rate control loop (in process, no server).

    python examples/05_stream_control_loop.py

Every tick (the model's dt: 100 Hz) the sensor gives one frame of the partner (a held-out recording plus
tracker noise), `stream.update(frame)` returns the prediction, and the robot (a kinematic servo of the
simulated 3-joint arm) moves towards the predicted posture *now*.  When the estimated phase reaches 1 the
movement is over and the loop stops updating (frames of a partner standing still would stretch it).  The predicted std
of the final posture slows the robot while the prediction is uncertain; an out-of-range frame stops it.  Every tick
starts by waiting for its time, so that every branch (also the out-of-range one, which skips the rest of the tick) keeps
the rate (``tests/sim/test_control_loops.py`` counts the ticks on a fake clock).
"""
import time

import numpy as np

import interprim as ip
from interprim.sim import controlled_arm, highfive_recordings

model = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=10).fit(highfive_recordings(30, seed=0))
truth = highfive_recordings(1, seed=7, region="test", noise=0.0)[0]
rng = np.random.default_rng(0)
arm = controlled_arm()
q = arm.rest.copy()  # the robot's joints (radians)
dt, ctrl = model.dt_, model.controlled_dofs_
rollout = p = None
stream = model.stream(robot_state=q)
caution, latency, n_ticks = 0.2, [], len(truth) + 30  # 0.3 s more: the partner holds its hand up
held = False
next_tick = time.perf_counter()
for k in range(n_ticks):
    next_tick += dt  # fixed rate: wait for this tick first, so that no branch below can skip the wait
    time.sleep(max(0.0, next_tick - time.perf_counter()))
    frame = truth[min(k, len(truth) - 1), :2] + rng.normal(0, 0.002, 2)  # the sensor: 2 mm tracker noise
    tic = time.perf_counter()
    if p is None or p.phase < 1.0:  # once the movement is over (phase 1), more frames of a still partner
        p = stream.update(frame)  # would stretch it: keep the last prediction
        if rollout is None:
            rollout = p.mean_rollout(101, ctrl)  # the mean trajectory on a fixed grid, built once
        Y = rollout(p)  # (101, 3) robot joints over normalised time 0..1
        latency.append(time.perf_counter() - tic)
    q_ref = np.array([np.interp(p.normalised_time, np.linspace(0, 1, 101), Y[:, c]) for c in range(3)])
    if p.out_of_range:  # wrong units / frame / columns, or a partner unlike the demonstrations: do not move
        if not held:
            print(f"tick {k}: input out of range ({p.input_distance:.1f} stds): robot holds")
            held = True
        continue  # the next tick still waits for its time: the loop keeps its rate
    if k % 10 == 0:  # the std costs a covariance (~1 ms here): every 10th tick is enough to set the caution
        sd = float(p.std(2)[-1, ctrl].max())  # calibrated std of the final posture, radians
        caution = np.clip(1.0 - sd / 0.3, 0.2, 1.0)  # 0.3 rad of doubt or more: move at 20 % speed
    q = q + caution * min(1.0, dt / 0.05) * (q_ref - q)  # servo with a 50 ms time constant, scaled by caution

lat = 1e3 * np.array(latency)
robot_hand, goal = arm.hand(q), arm.hand(truth[-1, 2:])  # the true robot ends at the high-five point
print(f"{n_ticks} ticks at {1 / dt:.0f} Hz, {len(lat)} updates: latency median {np.median(lat):.2f} ms, "
      f"p99 {np.percentile(lat, 99):.2f} ms")
print(f"final joint error {np.abs(q - truth[-1, 2:]).max():.3f} rad; "
      f"robot hand {100 * np.linalg.norm(robot_hand - goal):.1f} cm "
      f"from the true high-five point; partner's hand {100 * np.linalg.norm(truth[-1, :2] - goal):.1f} cm from it")
