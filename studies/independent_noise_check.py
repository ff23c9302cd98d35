"""The noise table's headline checked the way a user would meet it, outside the tool's own metrics.

Writes the tri-stable NES recordings (0.5 mm base sweep, seed 0) at 60 and 20 dB to plain NPZ
files, runs `gmr fit` on them with default options (a subprocess, as from a shell), reads the
written model JSON, and integrates the relative L2 error of its restoring force per unit mass
against Eq. (23) with `scipy.integrate.quad` (numpy polynomials; nothing from gmr_jax but the
data generator and the CLI). Prints the error and the warnings the model file carries.

Run: python studies/independent_noise_check.py
"""

import json
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np
from scipy.integrate import quad

import gmr_jax as g

ALPHA = np.array([-0.9, 168.6, 575.1, -2e5, -5e4, 6.5e7, 7.6e5, -4.7e9])  # Eq. (23), Table 1 (N)
MASS = 0.035  # kg


def main():
    system = g.systems.tristable_nes()
    lo, hi = (float(v) for v in system.x_range[0])
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        for snr in (60, 20):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                recs = g.systems.make_recordings(system, 5e-4, snr_db=snr, seed=0)
            files = []
            for r in recs:
                files.append(d / f"nes{snr}_{r.name}.npz")
                np.savez(files[-1], t=r.t, x=r.x, v=r.v, a=r.a, base_acc=r.base_acc)
            model = d / f"model{snr}.json"
            subprocess.run([sys.executable, "-m", "gmr_jax._cli._main", "fit", *map(str, files), "--out", str(model)],
                           check=True, capture_output=True)
            m = json.loads(model.read_text())
            k = np.zeros(1 + max(t["order"] for t in m["terms"]))
            for t in m["terms"]:
                if t["physics"] == "stiffness":
                    k[t["order"]] = t["coefficient"]

            def fitted(x, k=k, mass=m["masses"][0]):
                return np.polynomial.polynomial.polyval(x, k) / mass

            def truth(x):
                return np.polynomial.polynomial.polyval(x, ALPHA) / MASS

            num = quad(lambda x: (fitted(x) - truth(x)) ** 2, lo, hi, limit=200)[0]
            den = quad(lambda x: truth(x) ** 2, lo, hi, limit=200)[0]
            print(f"{snr} dB: restoring-force error per unit mass (scipy quad over [{lo:.4f}, {hi:.4f}]) "
                  f"{100 * np.sqrt(num / den):.3g} %; warnings in the model file: {m.get('warnings', [])}")


if __name__ == "__main__":
    main()
