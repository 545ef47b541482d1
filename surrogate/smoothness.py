"""Smoothness along lines in design space: the surrogate's gradient beside the simulator's differences.

For a few poses, random lines ``d(t) = d0 + t u`` (``u`` a random unit vector in the 22-dimensional
ln E space, ``d0`` drawn so that the line stays in the printable range) are sampled at evenly spaced
``t``. At every point the surrogate gives L_opt (:class:`~mjcodesign.surrogate.inference.DesignLoss`)
and its gradient; the simulator (``mjcodesign.jobs.run_jobs`` on MuJoCo C, the dataset's scenario)
gives its outcome, on which the same L_opt is evaluated (contact as 0/1). Reported per line: the
surrogate's gradient norm and directional derivative ``u · ∇L``, the simulator's finite differences
``ΔL / Δt`` between neighbouring points, both curves' total variation, and the success flips the
simulator shows along the line. The summary gives medians over the lines, the mean total variation,
and the agreement of the two curves' least-squares slopes along the lines: Pearson's and Spearman's
correlation (``None`` where either set of slopes is constant) and the share of lines where the signs
agree: how far the surrogate's design gradient points where the simulator's outcome moves. A few
lines say little: the median total variation of one network measured 0.19 on 4 lines and 3.3 on 64
(docs/benchmarks.md), so the report's default is 16 poses with 4 lines each.
"""

from __future__ import annotations

import numpy as np
import torch

from mjcodesign.data.config import DatagenConfig
from mjcodesign.design.stiffness import LOG_E_MAX, LOG_E_MIN, N_LOG_E, Stiffness
from mjcodesign.errors import DesignError
from mjcodesign.jobs import GraspJob, load_grasp_object, run_jobs
from mjcodesign.models.types import GripperPose
from mjcodesign.sim import get_backend
from mjcodesign.surrogate.data import GraspData
from mjcodesign.surrogate.inference import DesignLoss, GraspBatch, Poses, Surrogate

__all__ = ["design_lines", "smoothness"]


def design_lines(
    rng: np.random.Generator, lines: int, points: int, length: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(designs (lines, points, 22), directions (lines, 22), t (points,)) of random lines of ``length``."""
    if not (0 < length < LOG_E_MAX - LOG_E_MIN) or points < 2 or lines < 1:
        raise DesignError("a line needs points >= 2 and a length in (0, 3.5) of ln E")
    t = np.linspace(-length / 2, length / 2, points)
    u = rng.normal(size=(lines, N_LOG_E))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    half = length / 2  # |u_i| <= 1, so d0 this far inside the range keeps the line inside
    d0 = rng.uniform(LOG_E_MIN + half, LOG_E_MAX - half, size=(lines, N_LOG_E))
    return d0[:, None, :] + t[None, :, None] * u[:, None, :], u, t


def _sim_losses(outs, up: np.ndarray, loss: DesignLoss) -> np.ndarray:
    force = torch.tensor([o.body_force for o in outs], dtype=torch.float64)
    disp = torch.tensor([o.displacement for o in outs], dtype=torch.float64)
    contact = torch.tensor([float(o.ground_contact) for o in outs], dtype=torch.float64)
    upt = torch.tensor(np.repeat(up[None], len(outs), axis=0), dtype=torch.float64)
    return loss.rows(force, disp, contact, upt).numpy()


def _correlation(a: np.ndarray, b: np.ndarray) -> float | None:
    """Pearson's r, or ``None`` when it is undefined (fewer than 2 values, or either is constant)."""
    if len(a) < 2 or np.ptp(a) == 0 or np.ptp(b) == 0:
        return None
    return float(np.corrcoef(a, b)[0, 1])


def smoothness(
    surrogate: Surrogate,
    data: GraspData,
    poses: np.ndarray,
    *,
    lines: int = 2,
    points: int = 9,
    length: float = 1.0,
    seed: int = 0,
    cache_dir=None,
    loss: DesignLoss | None = None,
) -> dict:
    """Lines through design space at the pose rows ``poses`` of ``data`` (module docstring)."""
    loss = loss or DesignLoss()
    manifest = data.manifest
    config = DatagenConfig.from_dict(manifest["config"])
    backend = get_backend("mujoco")
    rng = np.random.default_rng(seed)
    rows = []
    for p in np.asarray(poses, dtype=int):
        o = int(data.pose_keys[p, 0])
        entry = manifest["objects"][o]
        obj = load_grasp_object(
            entry["source"],
            float(data.pose_density[p]),
            seed=config.object_seed,
            cache_dir=cache_dir,
        )
        designs, u, t = design_lines(rng, lines, points, length)
        pose = GripperPose.from_matrix(data.palm[p], tuple(data.openings[p]))
        flat = designs.reshape(-1, N_LOG_E)
        jobs = [
            GraspJob(obj=obj, pose=pose, design=Stiffness(d), finger_model=config.model,
                     scenario=config.scenario, density=float(data.pose_density[p]), geometry=config.geometry)
            for d in flat
        ]  # fmt: skip
        outs = run_jobs(jobs, backend)
        l_sim = _sim_losses(outs, data.up[p], loss).reshape(lines, points)
        ok = np.array([o.success for o in outs]).reshape(lines, points)
        batch = surrogate.prepare(GraspBatch(Poses.of(data.poses, [p]), [0], [data.pose_density[p]]))
        for k in range(lines):
            res = [surrogate.loss_and_grad(d, batch, loss) for d in designs[k]]
            l_sur = np.array([r.loss for r in res])
            grads = np.array([r.grad for r in res])
            dt = float(t[1] - t[0])
            fd = np.diff(l_sim[k]) / dt
            rows.append({
                "object": entry.get("name", entry["source"]),
                "pose_row": int(p),
                "line": k,
                "t": t.tolist(),
                "surrogate_loss": l_sur.tolist(),
                "simulator_loss": l_sim[k].tolist(),
                "simulator_success": ok[k].tolist(),
                "grad_norm_mean": float(np.linalg.norm(grads, axis=1).mean()),
                "grad_norm_max": float(np.linalg.norm(grads, axis=1).max()),
                "surrogate_slope_max": float(np.abs(grads @ u[k]).max()),
                "simulator_fd_abs_mean": float(np.abs(fd).mean()),
                "simulator_fd_abs_max": float(np.abs(fd).max()),
                "surrogate_total_variation": float(np.abs(np.diff(l_sur)).sum()),
                "simulator_total_variation": float(np.abs(np.diff(l_sim[k])).sum()),
                "simulator_success_flips": int(np.sum(ok[k][1:] != ok[k][:-1])),
            })  # fmt: skip
    summary = {
        key: float(np.median([r[key] for r in rows]))
        for key in ("grad_norm_mean", "surrogate_slope_max", "simulator_fd_abs_max",
                    "surrogate_total_variation", "simulator_total_variation")
    }  # fmt: skip
    summary["simulator_success_flips_total"] = int(sum(r["simulator_success_flips"] for r in rows))
    tv = np.array([[r["surrogate_total_variation"], r["simulator_total_variation"]] for r in rows])
    slopes = np.array(
        [[np.polyfit(r["t"], r[k], 1)[0] for k in ("surrogate_loss", "simulator_loss")] for r in rows]
    )
    summary["lines"] = len(rows)
    summary["surrogate_total_variation_mean"] = float(tv[:, 0].mean())
    summary["simulator_total_variation_mean"] = float(tv[:, 1].mean())
    summary["slope_correlation"] = _correlation(slopes[:, 0], slopes[:, 1])
    from scipy.stats import rankdata  # lazily, as everywhere in the package

    summary["slope_rank_correlation"] = _correlation(rankdata(slopes[:, 0]), rankdata(slopes[:, 1]))
    summary["slope_sign_agreement"] = float(np.mean(np.sign(slopes[:, 0]) == np.sign(slopes[:, 1])))
    return {
        "lines": rows,
        "median": summary,
        "points": points,
        "length": length,
        "step": float(length / (points - 1)),
    }
