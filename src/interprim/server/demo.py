"""Models fitted at start-up for ``interprim serve --demo`` (and the browser test).

* ``highfive``: the simulated high-five of :mod:`interprim.sim` (observed arm: 2
  joints, controlled arm: 3 joints), with held-out test interactions for the
  page's "replay" button.
* ``letter_c``, ``letter_s``, ``letter_u``: single-agent handwriting models on
  synthetic pen strokes (each demonstration is a randomly scaled, rotated,
  shifted and time-warped letter), for the page's handwriting tab, where the
  server recognises which letter is being drawn (``open`` with ``"recognise"``).
"""

from __future__ import annotations

import numpy as np

from .models import entry_for, replay_json

LETTERS = ("c", "s", "u")


def _letter_path(letter: str, s: np.ndarray) -> np.ndarray:
    """Canonical stroke of ``letter`` at normalised times ``s`` (0..1), in a unit box, y up."""
    if letter == "c":
        a = np.deg2rad(60 + 240 * s)  # counter-clockwise from upper right to lower right
        return np.stack([0.5 + 0.4 * np.cos(a), 0.5 + 0.4 * np.sin(a)], axis=1)
    if letter == "s":
        # upper arc counter-clockwise from upper right, then lower arc clockwise
        out = np.empty((s.size, 2))
        up = s < 0.5
        a = np.deg2rad(30 + 240 * (s[up] / 0.5))
        out[up] = np.stack([0.5 + 0.22 * np.cos(a), 0.72 + 0.22 * np.sin(a)], axis=1)
        b = np.deg2rad(90 - 240 * ((s[~up] - 0.5) / 0.5))
        out[~up] = np.stack([0.5 + 0.22 * np.cos(b), 0.28 + 0.22 * np.sin(b)], axis=1)
        return out
    if letter == "u":
        a = np.pi + np.pi * s  # half circle at the bottom, with straight sides
        x = 0.5 + 0.32 * np.cos(a)
        y = np.where(s < 0.25, 0.9 - (s / 0.25) * 0.5, np.where(s > 0.75, 0.4 + ((s - 0.75) / 0.25) * 0.5, 0.0))
        mid = (s >= 0.25) & (s <= 0.75)
        t = (s[mid] - 0.25) / 0.5
        ang = np.pi + np.pi * t
        x = np.where(s < 0.25, 0.18, np.where(s > 0.75, 0.82, x))
        x[mid] = 0.5 + 0.32 * np.cos(ang)
        y[mid] = 0.4 + 0.32 * np.sin(ang)
        return np.stack([x, y], axis=1)
    raise ValueError(f"unknown letter {letter!r}; known: {LETTERS}")


def synthetic_letters(letter: str, n: int, seed: int = 0, dt: float = 0.01) -> list:
    """``n`` synthetic pen strokes ``(T_i, 2)`` of ``letter`` (x, y in a unit box, y up)."""
    rng = np.random.default_rng([seed, ord(letter)])
    demos = []
    for _ in range(int(n)):
        T = int(round(rng.uniform(0.8, 1.2) / dt))
        u = np.linspace(0.0, 1.0, T)
        warp = u + rng.uniform(-0.08, 0.08) * np.sin(np.pi * u)  # monotone time warp
        p = _letter_path(letter, np.clip(warp, 0.0, 1.0)) - 0.5
        ang = rng.uniform(-0.12, 0.12)
        R = np.array([[np.cos(ang), -np.sin(ang)], [np.sin(ang), np.cos(ang)]])
        p = (p @ R.T) * rng.uniform(0.85, 1.15) + 0.5 + rng.uniform(-0.04, 0.04, size=2)
        demos.append(p)
    return demos


def _geometry(arm) -> dict:
    return {
        "name": arm.name,
        "link_lengths": arm.link_lengths.tolist(),
        "base": np.asarray(arm.base, dtype=float).tolist(),
        "base_angle": float(getattr(arm, "base_angle", 0.0)),
        "sign": -1.0 if getattr(arm, "mirror", False) else 1.0,
        "rest": np.asarray(arm.rest, dtype=float).tolist(),
        "joint_limits": np.asarray(arm.joint_limits, dtype=float).tolist(),
    }


def highfive_world() -> dict:
    """Arm geometry of :mod:`interprim.sim` for the page (same link lengths as the simulator)."""
    from ..sim import GOAL_BOX, controlled_arm, observed_arm

    return {
        "observed_arm": _geometry(observed_arm()),
        "controlled_arm": _geometry(controlled_arm()),
        "goal_box": [list(GOAL_BOX[0]), list(GOAL_BOX[1])],
    }


def highfive_model(n_train: int = 40, n_test: int = 4, seed: int = 0, n_basis: int = 15, progress: bool = False,
                   n_jobs: int = 1):
    """Fit the high-five IP on simulated interactions; returns a :class:`ModelEntry` with replay data."""
    import interprim as ip

    from ..sim import highfive_split

    train, test = highfive_split(n_train, n_test, seed=seed, progress=progress, n_jobs=n_jobs)
    # the page's input is a dragged mouse pointer (pixel-quantised, irregular): ~0.01 rad of noise that the
    # simulated demonstrations do not have
    model = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=n_basis, input_noise=0.01)
    model.fit(train.demos, dt=train.dt)
    oa = test.observed_arm
    names = ["obs_shoulder", "obs_elbow", "ctrl_shoulder", "ctrl_elbow", "ctrl_wrist"]
    units = ["rad"] * 5
    replay = replay_json(model, test.demos, names=names, units=units, source="held-out simulated interactions")
    for it, d, g in zip(replay["interactions"], test.demos, test.goals):
        it["goal"] = np.asarray(g, dtype=float).tolist()
        it["observed_hand_path"] = np.round(oa.hand(d[:, :2]), 6).tolist() if hasattr(oa, "hand") else None
    meta = {"title": "Simulated high-five (interprim.sim)", "world": "highfive", "replay": replay,
            "columns": names, "units": units}
    return entry_for("highfive", model, source="demo: interprim.sim", kind="interaction", meta=meta)


def letter_models(n: int = 20, seed: int = 0, n_basis: int = 15) -> dict:
    """Single-agent handwriting models ``letter_<x>`` fitted on :func:`synthetic_letters`."""
    import interprim as ip

    out = {}
    for letter in LETTERS:
        demos = synthetic_letters(letter, n, seed=seed)
        model = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=n_basis, input_noise=0.01)  # mouse input
        model.fit(demos, dt=0.01)
        test = synthetic_letters(letter, 2, seed=seed + 1)
        meta = {
            "title": f"Letter '{letter}' (synthetic strokes)",
            "world": "handwriting",
            "extent": [[-0.1, 1.1], [-0.1, 1.1]],
            "columns": ["x", "y"],
            "replay": replay_json(model, test, names=["x", "y"], source="synthetic test strokes"),
        }
        name = f"letter_{letter}"
        out[name] = entry_for(name, model, source="demo: synthetic letters", kind="single", meta=meta)
    return out


def demo_models(seed: int = 0, n_train: int = 40, progress: bool = False, n_jobs: int = 1) -> dict:
    """All demo models (high-five + letters), name -> ModelEntry."""
    models = {}
    hf = highfive_model(n_train=n_train, seed=seed, progress=progress, n_jobs=n_jobs)
    models[hf.name] = hf
    models.update(letter_models(seed=seed))
    return models
