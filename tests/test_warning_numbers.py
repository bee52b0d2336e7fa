"""A warning names a mode by the frequency the modal table lists for it: the notebook's first run read
"1 of 3 modes (29.47 Hz) has 2.6 lines in its half-power band" for the mode listed at 29.43 Hz, because
the warning was written from the pLSCF pole before the pole was refined with its uncertainty
(modal.uncertainty.with_uncertainty), and the table lists the refined one."""

from __future__ import annotations

import re


def test_the_line_count_warning_quotes_the_listed_frequencies(tmp_path):
    import flexmodal as fm
    from flexmodal.fixtures.demo import store_test
    from flexmodal.fixtures.rig_sim import DEMO_RIG, HiddenEffect, simulate

    elbow = [HiddenEffect("joint_stiffness", "elbow", {"k_Nm_per_rad": 8000.0})]   # docs/python-api.md
    test = simulate(fm.load_rig(DEMO_RIG), {"theta_deg": 0.0}, excitation="random", duration_s=16.0,
                    effects=elbow, seed=0)
    store_test(tmp_path / "runs.h5", "theta0", test)
    ident = fm.identify(tmp_path / "runs.h5", fmin=5.0, fmax=450.0, max_order=20)
    listed = {f"{f:.4g}" for f in ident.table.freq_hz("theta0")}
    warning = next(w for w in ident.warnings if "half-power band" in w)
    quoted = re.search(r"modes? \(([^)]*) Hz\)", warning)[1].split(", ")
    detailed = [re.match(r"mode at (\S+) Hz: ", line)[1] for line in ident.modes["theta0"].details]
    assert quoted and set(quoted) <= listed, (warning, listed)
    assert detailed == quoted, (ident.modes["theta0"].details, listed)
    assert ident.modes["theta0"].freq_std_hz is not None   # the poles were refined (the case at issue)
