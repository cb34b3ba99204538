"""`python -m wanderland_nav.recon_eval`: the paper's reconstruction benchmark on any tool's output.

Thin Hydra entry point: compose conf/recon_eval.yaml, call `wanderland_nav.recon`, print the
table, write `recon_eval.{json,csv}`, a top-down PNG per scene and `recon_eval.rrd` to `out`.

Examples:
    python -m wanderland_nav.recon_eval pred=est.txt gt=groundtruth.txt            # TUM, stamps within 10 ms
    python -m wanderland_nav.recon_eval pred=vggt/sparse/0 gt=/data/wanderland/scene_01
    python -m wanderland_nav.recon_eval pred=preds/ gt=/data/wanderland/            # every scene: mean/median, SR
    python -m wanderland_nav.recon_eval nvs=renders/ gt=/data/wanderland/scene_01   # PSNR/SSIM(/LPIPS) on nvs_split
"""

from __future__ import annotations

from wanderland_nav.app import entry_point  # first: it readies the process (see app.py)

from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from wanderland_nav.compose import SCHEMAS, typed_config
from wanderland_nav.compose.cli import hydra_output_dir, quote_overrides
from wanderland_nav.geometry import up_vector
from wanderland_nav.gsfit.lpips import LPIPS
from wanderland_nav.recon import evaluate_paths
from wanderland_nav.recon.nvs import format_nvs, score_renders
from wanderland_nav.recon.report import write_results
from wanderland_nav.scene import load_scene
from wanderland_nav.viz.recon_plot import plot_trajectories
from wanderland_nav.viz.rerun_recon import write_recon_recording


def run(cfg: dict) -> dict:
    """Everything `main` does, on a plain dict (tests call it without Hydra). Returns what was written."""
    if cfg.get("gt") is None or (cfg.get("pred") is None and cfg.get("nvs") is None):
        raise ValueError("recon_eval needs gt=<path> and pred=<path> (poses) and/or nvs=<renders folder> (images)")
    out = Path(cfg["out"]) if cfg.get("out") else hydra_output_dir()
    bench = nvs = None
    if cfg.get("pred") is not None:
        bench = evaluate_paths(cfg["pred"], cfg["gt"], max_time_diff=float(cfg["max_time_diff"]),
                               time_offset=float(cfg["time_offset"]), rpe_delta=int(cfg["rpe_delta"]),
                               collinear_tol=float(cfg["collinear_tol"]), chunk_pairs=int(cfg["chunk_pairs"]),
                               device=str(cfg["device"]))
        print(bench.table(label=cfg.get("name") or Path(cfg["pred"]).name), flush=True)
    if cfg.get("nvs") is not None:
        nvs = _score_nvs(cfg)
    written = write_results(out, bench, nvs=nvs, meta={k: cfg.get(k) for k in ("pred", "gt", "nvs", "name")})
    if bench is not None and bench.results:
        written += _draw(out, bench, plot=bool(cfg.get("plot", True)), rerun=bool(cfg.get("rerun", True)))
    print("wrote " + ", ".join(str(p) for p in written))
    return {"bench": bench, "nvs": nvs, "written": written}


def _score_nvs(cfg: dict) -> dict:
    lpips = None
    lp = cfg.get("lpips") or {}
    if lp.get("backbone_path") and lp.get("lin_path"):
        lpips = LPIPS.from_files(lp["backbone_path"], lp["lin_path"])
    res = score_renders(load_scene(cfg["gt"]), cfg["nvs"], split=str(cfg["nvs_split"]),
                        holdout_every=int(cfg["nvs_holdout_every"]), downscale=float(cfg["nvs_downscale"]), lpips=lpips)
    print(format_nvs(res, label=cfg.get("name") or Path(cfg["nvs"]).name), flush=True)
    return res


def _draw(out: Path, bench, *, plot: bool, rerun: bool) -> list[Path]:
    written = []
    if plot:
        for r in bench.results:
            up = up_vector(r.up_axis) if r.up_axis else None
            title = f"{r.name}: T-ATE^S {r.metrics['t_ate_sim3']:.3f} m, {r.metrics['matched']} cameras"
            written.append(plot_trajectories(out / f"traj_{Path(r.name).stem}.png", r.gt_centers,
                                             r.pred_centers_sim3, up=up, title=title))
    if rerun:
        write_recon_recording(out / "recon_eval.rrd", bench.results)
        written.append(out / "recon_eval.rrd")
    return written


def run_config(cfg: DictConfig) -> dict:
    """`run` on the composed config, once it is typed (a typo or a wrong type fails here, with the key named)."""
    typed_config(cfg, SCHEMAS["recon_eval"])
    return run(OmegaConf.to_container(cfg, resolve=True))


main = entry_point("recon_eval", run_config, argv=quote_overrides)


if __name__ == "__main__":
    main()
