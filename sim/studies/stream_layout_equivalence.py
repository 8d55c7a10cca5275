#!/usr/bin/env python3
"""Statistical equivalence of two builds of the tracer (the rime random-stream layout, the
glazed arithmetic).

Runs `foisctl sim montecarlo` and `foisctl sim crlb` for ICE (default rime) with K independent seeds per
build (different seeds for the two builds), and compares, per thickness, the batch means of
mu_I1, mu_I2, var_I1, var_I2, cov and the CRLB: z = (new - old) / sqrt(SE_old^2 + SE_new^2),
SE = standard deviation of the K batch values / sqrt(K). Under equivalence about 5 % of the
|z| exceed 2 and 0.3 % exceed 3 (neighbouring thicknesses are correlated, so the counts
fluctuate more than for independent tests).

Usage: stream_layout_equivalence.py OLD_FOISCTL NEW_FOISCTL [K] [RUNS] [SEED_OLD] [SEED_NEW] [ICE]
(seeds SEED_OLD.. and SEED_NEW.., default 1001.. and 2001..; ICE rime, glazed or water)
"""
import csv, math, os, subprocess, sys, tempfile

ICE = "rime"

def run(binary, sub, seed, runs, out):
    subprocess.run([binary, "sim", sub, "--ice", ICE, "--runs", str(runs), "--seed", str(seed),
                    "--out", out], check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    with open(out) as f:
        return list(csv.DictReader(f))

def batches(binary, seeds, runs, tmp):
    out = []
    for s in seeds:
        mc = run(binary, "montecarlo", s, runs, os.path.join(tmp, "mc.csv"))
        cr = run(binary, "crlb", s, runs, os.path.join(tmp, "crlb.csv"))
        rows = []
        for m, c in zip(mc, cr):
            rows.append({
                "d": float(m["thickness_mm"]),
                "mu_I1": float(m["mean_i1_ua"]), "mu_I2": float(m["mean_i2_ua"]),
                "var_I1": float(m["var_i1"]), "var_I2": float(m["var_i2"]),
                "cov": float(m["cov_i1_i2"]), "crlb": float(c["crlb_std_mm"]),
            })
        out.append(rows)
    return out

def mean_se(values):
    k = len(values)
    m = sum(values) / k
    sd = math.sqrt(sum((v - m) ** 2 for v in values) / (k - 1))
    return m, sd / math.sqrt(k)

def main():
    global ICE
    if not 3 <= len(sys.argv) <= 8:
        sys.exit(__doc__.strip().splitlines()[-2] + "\n" + __doc__.strip().splitlines()[-1])
    old, new = sys.argv[1], sys.argv[2]
    for b in (old, new):
        if not (os.path.isfile(b) and os.access(b, os.X_OK)):
            sys.exit(f"not an executable foisctl: {b}")
    try:
        k, runs, seed_old, seed_new = (
            int(sys.argv[i]) if len(sys.argv) > i else d
            for i, d in ((3, 10), (4, 1000), (5, 1001), (6, 2001))
        )
    except ValueError as e:
        sys.exit(f"K, RUNS and the seeds are whole numbers: {e}")
    if len(sys.argv) > 7:
        ICE = sys.argv[7]
        if ICE not in ("rime", "glazed", "water"):
            sys.exit(f"ICE is rime, glazed or water, not {ICE}")
    if k < 5 or runs < 2:
        sys.exit("K must be at least 5 (the standard error comes from the spread of the K "
                 "batches; 10-20 give usable z) and RUNS at least 2")
    with tempfile.TemporaryDirectory() as tmp:
        a = batches(old, range(seed_old, seed_old + k), runs, tmp)
        b = batches(new, range(seed_new, seed_new + k), runs, tmp)
    keys = ["mu_I1", "mu_I2", "var_I1", "var_I2", "cov", "crlb"]
    print(f"{ICE}: {k} seeds x {runs} accretions per build; z per thickness (d > 0)")
    print(f"{'quantity':8} {'n':>4} {'|z|>2':>6} {'|z|>3':>6} {'max|z|':>7} {'chi2/n':>7}")
    rows = []
    for key in keys:
        zs = []
        for i in range(1, len(a[0])):
            va = [r[i][key] for r in a]
            vb = [r[i][key] for r in b]
            if any(math.isnan(v) for v in va + vb):
                continue
            ma, sa = mean_se(va)
            mb, sb = mean_se(vb)
            se = math.hypot(sa, sb)
            if se > 0:
                zs.append(((mb - ma) / se, a[0][i]["d"], ma, mb, se))
        n = len(zs)
        big2 = sum(abs(z[0]) > 2 for z in zs)
        big3 = sum(abs(z[0]) > 3 for z in zs)
        worst = max(zs, key=lambda z: abs(z[0]))
        chi2 = sum(z[0] ** 2 for z in zs) / n
        print(f"{key:8} {n:4d} {big2:6d} {big3:6d} {abs(worst[0]):7.2f} {chi2:7.2f}"
              f"   (worst at {worst[1]:.1f} mm: old {worst[2]:.5g}, new {worst[3]:.5g} ± {worst[4]:.2g})")
        rows.append(zs)
    print("selected thicknesses (old -> new, ± SE of the difference):")
    for d in (1.0, 2.0, 3.0, 5.0, 10.0, 15.0):
        parts = []
        for key, zs in zip(keys, rows):
            z = next((z for z in zs if abs(z[1] - d) < 1e-6), None)
            if z:
                parts.append(f"{key} {z[2]:.4g}->{z[3]:.4g} (z {z[0]:+.1f})")
        print(f"  {d:4.1f} mm: " + ", ".join(parts))

if __name__ == "__main__":
    main()
