"""16-coefficient MCMC samplers compared on replicate 1 of the coverage study (docs/uncertainty.md sect. 2).

    OPENBLAS_NUM_THREADS=1 nice python -m studies.compare_mcmc16_samplers
"""
import time, warnings, numpy as np
warnings.simplefilter("ignore")
from shipid.campaign import member_seeds
from shipid.identify import EKFIdentifier
from shipid.identify.batch import OutputErrorRefiner
from studies.coverage import COVERAGE_RECIPES
from shipid.uncertainty.posterior import sample_posterior
from shipid.models import get_model
from shipid.synthetic import KCS_NOISE_STD, make_trial
truth = get_model("kcs-response", "synthetic-truth")
s = member_seeds(2026, 1)[0]
rng = np.random.default_rng(s)
logs = [make_trial(truth, r, rng, dict(KCS_NOISE_STD))[0] for r in COVERAGE_RECIPES]
start = truth.with_params(truth.params * (1 + 0.3 * rng.standard_normal(truth.np)))
ident = EKFIdentifier(start, n_passes=2).fit(logs); res = ident.result(); names = list(res.cov.index)
t = time.process_time()
oe = OutputErrorRefiner(ident.to_model(), estimate=names, meas_std=ident.meas_std_.to_dict(), channels=["u","v","r"],
    jacobian="tangent", max_nfev=50, input_hold=ident.input_hold, estimate_x0=True).fit(logs, start=ident)
print("OE fit CPU-s %.2f" % (time.process_time() - t))
runs = {"laplace proposal, 800/100, 48 walkers": dict(steps=800, burn=100, walkers=48, moves="independence", proposal=oe),
        "t from DE burn-in, 1000/300, 48 walkers": dict(steps=1000, burn=300, walkers=48, moves="independence"),
        "t from DE burn-in, 2000/1000, 48 walkers": dict(steps=2000, burn=1000, walkers=48, moves="independence"),
        "DE moves, 2000/1000, 48 walkers": dict(steps=2000, burn=1000, walkers=48, moves="de")}
for k, kw in runs.items():
    t = time.process_time()
    p = sample_posterior(res, logs, sample_x0=True, use_prior=False, seed=5, **kw)
    c = time.process_time() - t
    d = p.diagnostics
    print(f"{k}: {c:.1f} CPU-s, acceptance {d['acceptance_mean']:.3f}, tau_max {d['tau_max']:.1f}, ESS_min {d['ess_min']:.0f}, "
          f"R-hat {d['rhat_max']:.4f}, ESS/CPU-s {d['ess_min']/c:.0f}, {p.message[:60]}")
