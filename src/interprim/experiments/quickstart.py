"""Core figures on the built-in synthetic two-agent data (issue: the IP core).

Run ``python -m interprim.experiments.quickstart``.  Prints, for the paper's
configuration with both DTW reference choices ("mean" of the time-normalised
demonstrations vs a single demonstration as in the paper), for the library's
defaults (positions, ``sigma2="cv"``) and for the defaults with the likelihood
phase:

- the phase error on held-out demonstrations (different goals *and*
  durations) at 10-100 % observed, and on time-stretched (0.7-1.5x) prefixes
  of the reference movement itself;
- the controlled agent's MSE at 10/30/60/100 % observed with the estimated phase and
  with the true (oracle) phase, against the prior-mean baseline.
"""

from __future__ import annotations

import numpy as np


def _mse_ctrl(pred, demo, n_obs_cols):
    from interprim.core.preprocessing import time_normalise

    gt = time_normalise(demo, 100)
    return float(np.mean((pred.trajectory(100)[:, n_obs_cols:] - gt[:, n_obs_cols:]) ** 2))


PAPER = dict(observation="forcing", sigma2="residual", phase_method="dtw")
CONFIGS: dict[str, dict] = {
    "paper, reference=mean": dict(PAPER, reference="mean"),
    "paper, reference=demo 0": dict(PAPER, reference=0),
    "positions, sigma2=cv, DTW phase": dict(phase_method="dtw"),
    "library defaults (positions, sigma2=cv, likelihood phase)": dict(),
}


def run(n_train: int = 30, n_test: int = 20, seed: int = 0, fractions=(0.1, 0.3, 0.6, 1.0), configs=None) -> dict:
    import interprim as ip
    from interprim.core.preprocessing import time_normalise
    from interprim.synthetic import two_agent_demos

    train = two_agent_demos(n_train, seed=seed)
    test = two_agent_demos(n_test, seed=seed + 1000)
    out = {}
    for name, kw in (configs or CONFIGS).items():
        m = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=20, **kw).fit(train, dt=0.01)
        rows = {}
        prior = float(np.mean([_mse_ctrl(m.predict(d[:1, :2]), d, 2) for d in test]))
        for p in fractions:
            ph_err, e_dtw, e_orc = [], [], []
            for d in test:
                M = max(int(round(p * (len(d) - 1))) + 1, 3)
                true = (M - 1) / (len(d) - 1)
                pr = m.predict(d[:M, :2])
                ph_err.append(abs(pr.phase - true))
                e_dtw.append(_mse_ctrl(pr, d, 2))
                e_orc.append(_mse_ctrl(m.predict(d[:M, :2], phase=true), d, 2))
            rows[p] = {"phase_error": float(np.mean(ph_err)), "ctrl_mse_dtw": float(np.mean(e_dtw)),
                       "ctrl_mse_oracle_phase": float(np.mean(e_orc)), "ctrl_mse_prior_mean": prior}
        stretch_err = []
        for stretch in (0.7, 0.85, 1.0, 1.2, 1.5):
            T = int(round((len(m.reference_) - 1) * stretch)) + 1
            mov = time_normalise(m.reference_, T)
            for frac in (0.2, 0.4, 0.6, 0.8):
                M = int(round(frac * (T - 1))) + 1
                stretch_err.append(abs(m.predict(mov[:M]).phase - (M - 1) / (T - 1)))
        out[name] = {"by_fraction": rows, "stretched_prefix_phase_error_mean": float(np.mean(stretch_err)),
                         "stretched_prefix_phase_error_max": float(np.max(stretch_err))}
    return out


def main():
    res = run()
    for name, r in res.items():
        print(f"{name}: time-stretched prefixes (0.7-1.5x): phase error mean "
              f"{r['stretched_prefix_phase_error_mean']:.4f}, max {r['stretched_prefix_phase_error_max']:.4f}")
        print(f"{'observed':>9} {'phase err':>10} {'ctrl MSE (est.)':>15} {'ctrl MSE (true phase)':>22} "
              f"{'prior mean':>11}")
        for p, row in r["by_fraction"].items():
            print(f"{p:>9.0%} {row['phase_error']:>10.4f} {row['ctrl_mse_dtw']:>15.5f} "
                  f"{row['ctrl_mse_oracle_phase']:>22.6f} {row['ctrl_mse_prior_mean']:>11.5f}")


if __name__ == "__main__":
    main()
