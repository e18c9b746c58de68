#!/usr/bin/python3
"""Generates tests/data/head/lookaround_72hz.csv: a SIMULATED head trace, not
a recording of a real person (we have no tracker). It is made by a model
independent of client/pose/head_motion.cc, so predictors tuned on that
generator are checked on different dynamics:

* gaze targets (yaw uniform ±40°, pitch normal σ 7°, roll normal σ 2°) held
  for log-normal fixations (median 0.8 s); the head follows each target as a
  critically damped second-order system (natural frequency 11 rad/s) with the
  angular speed saturated at 240°/s, integrated at 1 kHz;
* small angular drift and postural sway: low-pass filtered noise;
* from 20 s to 31 s the person steps 1.0 m forward and back (minimum-jerk
  walk, vertical bob 1.5 cm at the 1.9 Hz step frequency);
* the eye sits 8 cm in front of and 10 cm above the neck pivot, so head turns
  move the eye;
* "tracker": 72 Hz nominal with ±0.6 ms timestamp jitter, 1% of the samples
  dropped, white noise σ 0.4 mm and 0.04°.

Run with /usr/bin/python3 (numpy); seed fixed, so the output is reproducible.
Columns: time_s, x_m, y_m, z_m, yaw_deg, pitch_deg, roll_deg (frames and
Euler convention: client/pose/head_pose.h).
"""
import numpy as np

rng = np.random.default_rng(20261122)
DT = 1e-3
DURATION = 45.0
n = int(DURATION / DT) + 1
t = np.arange(n) * DT

# Gaze targets and the head's second-order response.
targets = np.zeros((n, 3))
cur = np.zeros(3)
k = 0
while k < n:
    dwell = max(0.25, rng.lognormal(np.log(0.8), 0.5))
    m = min(n, k + int(dwell / DT))
    targets[k:m] = cur
    k = m
    if rng.random() < 0.3:
        cur = cur + np.array([rng.uniform(-8, 8), rng.uniform(-2, 2), rng.uniform(-0.5, 0.5)])
        cur[0] = np.clip(cur[0], -40, 40)
    else:
        cur = np.array([rng.uniform(-40, 40), np.clip(rng.normal(0, 7), -20, 20), np.clip(rng.normal(0, 2), -5, 5)])

wn, vmax = 11.0, 240.0
ang = np.zeros((n, 3))
vel = np.zeros(3)
a = np.zeros(3)
for i in range(n):
    acc = wn * wn * (targets[i] - a) - 2 * wn * vel
    vel = vel + acc * DT
    speed = np.linalg.norm(vel)
    if speed > vmax:
        vel *= vmax / speed
    a = a + vel * DT
    ang[i] = a


def lowpass_noise(sigma, tau, shape):
    """Twice low-passed white noise, scaled to standard deviation `sigma`."""
    x = rng.normal(0, 1, shape)
    alpha = DT / tau
    for _ in range(2):
        y = np.zeros_like(x)
        for i in range(1, shape[0]):
            y[i] = y[i - 1] + alpha * (x[i] - y[i - 1])
        x = y
    return x / (x[shape[0] // 10:].std(axis=0) + 1e-12) * sigma


ang += lowpass_noise(0.4, 0.4, (n, 3))
sway = lowpass_noise(0.01, 1.5, (n, 3)) * np.array([1.0, 1.0, 0.3])

# Walk forward 1 m and back between 20 s and 31 s.
walk = np.zeros((n, 3))


def minjerk(u):
    u = np.clip(u, 0, 1)
    return u ** 3 * (10 - 15 * u + 6 * u * u)


for t0, t1, x0, x1 in [(20.0, 24.0, 0.0, 1.0), (27.0, 31.0, 1.0, 0.0)]:
    sel = t >= t0
    u = (t[sel] - t0) / (t1 - t0)
    walk[sel, 0] = x0 + (x1 - x0) * minjerk(u)
speed = np.abs(np.gradient(walk[:, 0], DT))
walk[:, 2] = 0.015 * np.minimum(1.0, speed / 0.4) * np.sin(2 * np.pi * 1.9 * t)

# Eye position from the neck pivot and the head rotation.
yaw, pitch, roll = np.radians(ang[:, 0]), np.radians(ang[:, 1]), np.radians(ang[:, 2])
off = np.array([0.08, 0.0, 0.10])  # head frame: x forward, y left, z up
# world_from_head = Rz(yaw) Ry(-pitch) Rx(roll), applied to `off`.
x, y, z = off
y1, z1 = y * np.cos(roll) - z * np.sin(roll), y * np.sin(roll) + z * np.cos(roll)
x2, z2 = x * np.cos(-pitch) + z1 * np.sin(-pitch), -x * np.sin(-pitch) + z1 * np.cos(-pitch)
x3, y3 = x2 * np.cos(yaw) - y1 * np.sin(yaw), x2 * np.sin(yaw) + y1 * np.cos(yaw)
neck = np.array([0.0, 0.0, 1.58]) + sway + walk
eye = neck + np.stack([x3, y3, z2], axis=1)

# The tracker.
times = []
tk = 0.0
while tk < DURATION - 0.01:
    times.append(tk + rng.uniform(-0.0006, 0.0006))
    tk += 1 / 72
times = np.array([max(0.0, s) for s in times])
keep = rng.random(len(times)) > 0.01
times = times[keep]
idx = np.clip(np.round(times / DT).astype(int), 0, n - 1)

lines = [
    "# SIMULATED head trace (not a real recording): tests/data/head/make_trace.py,",
    "# seed 20261122. Looking around (second-order head response to gaze targets),",
    "# stepping 1 m forward and back at 20-31 s; 72 Hz tracker with jitter, drops and noise.",
    "time_s,x_m,y_m,z_m,yaw_deg,pitch_deg,roll_deg",
]
for s, i in zip(times, idx):
    p = eye[i] + rng.normal(0, 0.0004, 3)
    e = ang[i] + rng.normal(0, 0.04, 3)
    lines.append(f"{s:.6f},{p[0]:.5f},{p[1]:.5f},{p[2]:.5f},{e[0]:.4f},{e[1]:.4f},{e[2]:.4f}")
with open("lookaround_72hz.csv", "w") as f:
    f.write("\n".join(lines) + "\n")
print(len(times), "samples")
