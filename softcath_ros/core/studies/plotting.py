"""Shared chart pieces for the studies (matplotlib, Agg backend: no display needed)."""
from __future__ import annotations


def pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def category_panel(ax, rows: list[dict], title: str, ylabel: str = "R_C [mm]") -> None:
    """R_C per variant of one parameter, in the order given: baseline as a star, cases that did
    not converge or are infeasible as red crosses on the axis with their status."""
    labels = [r["label"] for r in rows]
    xs = range(len(rows))
    ok = [(x, r["radius_of_curvature_mm"]) for x, r in zip(xs, rows) if r["radius_of_curvature_mm"] is not None]
    if ok:
        ax.plot(*zip(*ok), "o-", color="C0")
    for x, r in zip(xs, rows):
        if r["baseline"] and r["radius_of_curvature_mm"] is not None:
            ax.plot([x], [r["radius_of_curvature_mm"]], "*", color="C1", ms=14, label="baseline")
        if r["radius_of_curvature_mm"] is None:
            ax.annotate("infeasible" if not r["feasible"] else "no conv.", (x, 0), xycoords=("data", "axes fraction"),
                        color="r", fontsize=7, ha="center", va="bottom", rotation=90)
    ax.set_xticks(list(xs))
    ax.set_xticklabels(labels, rotation=30, ha="right", fontsize=7)
    ax.set_title(title, fontsize=9)
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)


def save(fig, path: str, title: str) -> None:
    """Title, lay out, write the PNG and free the figure."""
    plt = pyplot()
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def where(design, ctx) -> str:
    """The part of every chart title that says what was solved: design, pressure, rung."""
    from ..units import PA_PER_BAR

    return f"{design.name}, {ctx.pressure / PA_PER_BAR:g} bar, rung {ctx.rung}"
