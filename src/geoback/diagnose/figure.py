"""Measured vs computed along each instrument, before and after adding the missing physics."""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def before_after_figure(d):
    obs = d.baseline_problem.obs
    blocks = obs.blocks
    ncols = min(len(blocks), 4)
    nrows = int(np.ceil(len(blocks) / ncols))
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.2 * ncols, 4.6 * nrows), squeeze=False)
    sigma = np.sqrt(np.diag(obs.covariance))
    after_label = "with " + " + ".join(s.hypothesis.title for s in d.accepted) if d.accepted else "baseline"
    row = 0
    for ax, b in zip(axes.ravel(), blocks):
        idx = np.arange(row, row + len(b.labels))
        row += len(b.labels)
        vertical = b.integration is not None and np.allclose(b.points[:, 0], b.points[0, 0])
        pos = -b.points[:, 1] if vertical else np.arange(1, len(idx) + 1)
        mm = 1e3
        meas = obs.measured[idx] * mm
        if vertical:
            ax.fill_betweenx(pos, meas - 2 * sigma[idx] * mm, meas + 2 * sigma[idx] * mm, color="0.85",
                             label="measured ± 2σ")
            ax.plot(meas, pos, "ko", ms=4, label="measured")
            ax.plot(d.baseline_fit.x[idx] * mm, pos, "--", color="tab:red", label="baseline model")
            ax.plot(d.final_fit.x[idx] * mm, pos, "-", color="tab:blue", label=after_label)
            ax.invert_yaxis()
            ax.set_xlabel(f"{b.labels[0].component} [mm]")
            ax.set_ylabel("depth [m]")
        else:
            ax.errorbar(pos, meas, yerr=2 * sigma[idx] * mm, fmt="ko", ms=4, label="measured ± 2σ")
            ax.plot(pos, d.baseline_fit.x[idx] * mm, "--", color="tab:red", label="baseline model")
            ax.plot(pos, d.final_fit.x[idx] * mm, "-", color="tab:blue", label=after_label)
            ax.set_xlabel("reading")
            ax.set_ylabel("displacement [mm]")
        ax.set_title(f"{b.kind} {b.name}")
        ax.grid(alpha=0.3)
    for ax in axes.ravel()[len(blocks):]:
        ax.axis("off")
    handles, labels = axes.ravel()[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=4, frameon=False)
    b, f = d.baseline_reliability, d.final_reliability
    fig.suptitle(f"{d.case}: χ²/dof {b.reduced_chi2:.3g} (p = {b.p_value:.2g}) → {f.reduced_chi2:.3g} "
                 f"(p = {f.p_value:.2g})")
    fig.tight_layout(rect=(0, 0.06, 1, 0.95))
    return fig


def plot_before_after(d, out: Path) -> list[Path]:
    from ..outputs import write_atomic
    import io

    fig = before_after_figure(d)
    paths = []
    for ext in ("png", "svg"):
        buf = io.BytesIO()
        fig.savefig(buf, format=ext, dpi=110)
        path = Path(out) / f"diagnosis.{ext}"
        write_atomic(path, buf.getvalue())
        paths.append(path)
    plt.close(fig)
    return paths
