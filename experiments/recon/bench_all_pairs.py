"""Time and peak memory of the all-pairs metrics (T-RTE m/deg, R-RTE, AUC@30) at thousands of cameras.

Each configuration runs in a fresh process so its peak RSS is its own:
    OMP_NUM_THREADS=2 PYTHONPATH=$PWD python experiments/recon/bench_all_pairs.py [--cameras 5000] [--threads 2]
Prints one line per chunk size: cameras, pairs, seconds, peak RSS over the post-setup RSS (MiB).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # as recon_eval sets it: no spinning threads on a shared CPU

def _child(n: int, chunk: int, threads: int) -> dict:
    import numpy as np
    import torch
    from scipy.spatial.transform import Rotation

    from wanderland_nav.recon.metrics import all_pairs

    torch.set_num_threads(threads)
    rng = np.random.default_rng(0)
    gt = np.tile(np.eye(4), (n, 1, 1))
    gt[:, :3, :3] = Rotation.random(n, random_state=0).as_matrix()
    gt[:, :3, 3] = np.cumsum(rng.normal(size=(n, 3)), axis=0)
    pred = gt.copy()
    pred[:, :3, 3] += rng.normal(scale=0.05, size=(n, 3))
    pred[:, :3, :3] = Rotation.from_rotvec(rng.normal(scale=0.02, size=(n, 3))).as_matrix() @ gt[:, :3, :3]
    all_pairs(gt[:50], pred[:50], chunk_pairs=chunk)  # warm-up (imports, first kernels)
    base = _rss_now_mib()
    t0 = time.perf_counter()
    out = all_pairs(gt, pred, chunk_pairs=chunk)
    dt = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # KiB on Linux -> MiB
    return {"cameras": n, "pairs": out["pairs"], "chunk_pairs": chunk, "seconds": round(dt, 2),
            "peak_over_setup_mib": round(peak - base, 1), "peak_rss_mib": round(peak, 1),
            "r_rte_deg": round(out["r_rte_deg"], 4), "auc30": round(out["auc30"], 4)}


def _rss_now_mib() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2 ** 20


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--cameras", type=int, default=5000)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--chunks", type=int, nargs="+", default=[1 << 16, 1 << 19, 1 << 21])
    ap.add_argument("--child", type=int, default=None)
    a = ap.parse_args()
    if a.child is not None:
        print(json.dumps(_child(a.cameras, a.child, a.threads)))
        return
    print(f"load average: {os.getloadavg()}")
    for c in a.chunks:
        r = subprocess.run([sys.executable, __file__, "--cameras", str(a.cameras), "--threads", str(a.threads),
                            "--child", str(c)], capture_output=True, text=True, check=True)
        print(r.stdout.strip())


if __name__ == "__main__":
    main()
