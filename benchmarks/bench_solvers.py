"""Benchmark: the dp, vp and exact solvers on the seed paper's SLA (not run by CI).

- vp at a fixed 30, 100 and 500 digits (``--digits``; goals on the 2-core reference
  machine: 30 digits <= 5 s, 500 digits <= 60 s; the seed paper reports 5 minutes in
  Maple at 500 digits and over an hour in MATLAB), and vp with its automatic precision
  (30 -> 60 -> ..., plus the rational recovery at twice the final digits);
- dp, with and without column scaling, at 50, 200 and 1000 samples: rank, ridge, and the
  error of its beta against vp's beta for the same permutation (60 digits);
- what if the SLA's four-bar were almost a parallelogram: dp and vp with D22 moved towards
  D12 + D13 (a copy of the geometry in memory; the mechanism file is not touched);
- exact and vp on the PUMA 560 (open chain) for comparison.

Each configuration runs in a fresh subprocess so that its peak resident memory
(``resource.getrusage``, which also sees python-flint's C allocations, unlike
tracemalloc) is its own.

Run: python benchmarks/bench_solvers.py [--quick]
"""

import argparse
import json
import platform
import resource
import subprocess
import sys
import time


def one(kind, mech_name, digits, samples, scale):
    """Run one configuration in this process; print a JSON line."""
    from baseparams import registry
    from baseparams.io.loader import resolve
    mech = resolve(mech_name)
    options = {"samples": samples}
    if kind == "vp":
        options.update(digits=digits, recover=digits is None)
    if kind == "dp":
        options.update(scale=scale)
    if kind == "whatif":
        return whatif(mech, str(digits))
    start = time.perf_counter()
    res = registry.solvers()[kind].item.solve(mech, **options)
    elapsed = time.perf_counter() - start
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    d = res.diagnostics
    out = {"kind": kind, "mech": mech_name, "digits": res.digits, "rank": res.rank,
           "certified": res.certified, "seconds": elapsed, "peak_mb": peak, "warnings": len(res.warnings)}
    if kind == "vp":
        out.update(ridge=d["ridge_decades"], trusted=d["trusted_digits"], runs=[r["digits"] for r in d["runs"]],
                   recovery=d["rational_recovery"].get("succeeded"))
    if kind == "dp":
        out.update(clear=d["ridge"]["clear"], gap=d["ridge"]["largest_ratio"],
                   gap_after=d["ridge"]["largest_gap_after"], error=dp_error(mech, samples, scale),
                   samples=d["samples"])
    print(json.dumps(out))


def whatif(mech, d22):
    """dp and vp on the SLA with D22 replaced (towards the parallelogram D22 = D12 + D13)."""
    from baseparams import registry
    from baseparams.io.loader import parse_mechanism
    text = open(mech.path).read()
    changed = text.replace('D22 = "0.2501"', f'D22 = "{d22}"')
    assert d22 == "0.2501" or changed != text, "the SLA file no longer has D22 = 0.2501"
    variant = parse_mechanism(changed, f"sla_suspension_D22_{d22}.toml")
    dp = registry.solvers()["dp"].item.solve(variant)
    vp = registry.solvers()["vp"].item.solve(variant, recover=False)
    ridge = dp.diagnostics["ridge"]
    print(json.dumps({"dp_rank": dp.rank, "gap": ridge["largest_ratio"], "gap_after": ridge["largest_gap_after"],
                      "clear": ridge["clear"], "dp_warnings": len(dp.warnings), "vp_rank": vp.rank,
                      "vp_certified": vp.certified, "runs": [r["digits"] for r in vp.diagnostics["runs"]],
                      "sigma_r_lower": vp.diagnostics["sigma_r_lower"]}))


def dp_error(mech, samples, scale):
    """Largest |beta_dp - beta| in scaled units (dp's unrounded beta), beta from vp at 60
    digits for dp's kept set; None when dp's rank is wrong (no beta to compare)."""
    from baseparams.numeric import certify
    from baseparams.numeric.backends import Arb, Float64
    from baseparams.plugins.solvers.dp.gautier import dp_gautier
    from baseparams.dynamics.trajectory import Trajectory, observation_matrix
    Wf, _ = observation_matrix(mech, Float64(), Trajectory.default(mech, samples=samples))
    res = dp_gautier(Wf, scale=scale)
    backend = Arb(60)
    W, _ = observation_matrix(mech, backend)
    with backend.activate():
        if certify.analyse(W, 60, approximate_spectrum=False).rank != res.rank:
            return None
        try:
            a = certify.analyse(W, 60, kept=res.kept, approximate_spectrum=False)
        except ValueError:
            return None                          # dp's kept columns are not independent
        worst = 0.0
        for i, k in enumerate(a.kept):
            for b, j in enumerate(a.eliminated):
                s = 2.0 ** (a.exponents[k] - a.exponents[j])
                worst = max(worst, abs(res.beta[i, b] - float(a.beta[i, b].mid())) * s)
        return worst


def spawn(*args):
    out = subprocess.run([sys.executable, __file__, "--one", *map(str, args)], capture_output=True, text=True)
    if out.returncode:
        raise RuntimeError(out.stderr)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="skip 500 digits and the auto run")
    parser.add_argument("--one", nargs=5, metavar=("KIND", "MECH", "DIGITS", "SAMPLES", "SCALE"),
                        help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        kind, mech, digits, samples, scale = args.one
        one(kind, mech, digits if kind == "whatif" else None if digits == "auto" else int(digits),
            None if samples == "default" else int(samples), scale == "scaled")
        return

    print(f"machine: {platform.processor() or platform.machine()}, python {platform.python_version()}")
    print("\nSLA suspension (200 samples, W 400 x 70), vp at fixed digits and automatic")
    print(f"{'solver':>14} {'time (s)':>9} {'peak MB':>8} {'rank':>5} {'cert':>5} {'ridge dec':>9} "
          f"{'beta digits':>12}  notes")
    configs = [("vp", 30), ("vp", 100)] + ([] if args.quick else [("vp", 500), ("vp", "auto")])
    for kind, digits in configs:
        r = spawn(kind, "sla_suspension", digits, "default", "scaled")
        digits_text = f"{r['trusted']['min']}-{r['trusted']['max']}"
        note = f"runs at {r['runs']} digits" + (f", rationals recovered: {r['recovery']}"
                                                if r["recovery"] is not None else "")
        label = f"vp {digits}" + (" digits" if digits != "auto" else "")
        print(f"{label:>14} {r['seconds']:9.2f} {r['peak_mb']:8.0f} {r['rank']:5d} {str(r['certified']):>5} "
              f"{r['ridge']:>9} {digits_text:>12}  {note}")

    print("\nSLA suspension, dp (numpy SVD) by sample count and column scaling;"
          "\nbeta error: largest |beta_dp - beta| (scaled units) against vp at 60 digits, same permutation")
    print(f"{'samples':>8} {'scaling':>9} {'time (s)':>9} {'peak MB':>8} {'rank':>5} {'largest gap':>12} "
          f"{'after':>6} {'clear':>6} {'warn':>5} {'beta error':>11}")
    for samples in (50, 200, 1000):
        for scale in ("scaled", "unscaled"):
            r = spawn("dp", "sla_suspension", 0, samples, scale)
            err = "-" if r["error"] is None else f"{r['error']:.2g}"
            print(f"{samples:8d} {scale:>9} {r['seconds']:9.2f} {r['peak_mb']:8.0f} {r['rank']:5d} "
                  f"{r['gap']:12.3g} {r['gap_after']:6d} {str(r['clear']):>6} {r['warnings']:5d} {err:>11}")

    print("\nWhat if the four-bar BDGF were almost a parallelogram (the seed paper's words)?"
          "\nThe SLA with only D22 changed (a copy in memory; D12 + D13 = 0.4016 makes it exact):")
    print(f"{'D22':>8} {'dp rank':>8} {'largest gap':>12} {'after':>6} {'clear':>6} {'dp warn':>8} "
          f"{'vp rank':>8} {'vp cert':>8} {'vp digits':>14} {'vp s_r >=':>10}")
    for d22 in ("0.2501", "0.39", "0.4", "0.4016"):
        r = spawn("whatif", "sla_suspension", d22, "default", "scaled")
        print(f"{d22:>8} {r['dp_rank']:8d} {r['gap']:12.3g} {r['gap_after']:6d} {str(r['clear']):>6} "
              f"{r['dp_warnings']:8d} {r['vp_rank']:8d} {str(r['vp_certified']):>8} {str(r['runs']):>14} "
              f"{r['sigma_r_lower']:>10}")

    print("\nPUMA 560 (open chain)")
    for kind, digits in (("exact", 0), ("vp", 30), ("dp", 0)):
        r = spawn(kind, "puma560", digits, "default", "scaled")
        print(f"{kind:>8} {r['seconds']:9.2f} s {r['peak_mb']:8.0f} MB  rank {r['rank']}"
              + (" (certified)" if r["certified"] else ""))


if __name__ == "__main__":
    main()
