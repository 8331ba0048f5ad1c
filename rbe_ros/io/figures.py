"""Figures in the style of the paper: blocks, interfaces with their kerns, nodal forces
coloured by sign and magnitude (blue compression, red tension) and interface resultants."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..analysis.assembly import Assembly
from ..rbe.result import Report


def draw_report(assembly: Assembly, report: Report, path, *, title: str = "",
                view: tuple[float, float] = (20.0, -60.0),
                force_scale: float | None = None) -> Path:
    """Write a PNG of ``report`` on ``assembly``; ``view`` is (elevation, azimuth) in deg.

    Nodal force arrows point along the force on block b, with length proportional to the
    force (the largest vertex force is drawn as a tenth of the scene size unless
    ``force_scale`` in m/N is given). Resultants are black arrows at the centre of pressure.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib import cm, colors
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

    fig = plt.figure(figsize=(8, 6.5), dpi=120)
    ax = fig.add_subplot(projection="3d")
    unstable = set(report.unstable_blocks)
    for b in assembly.blocks:
        polys = [f.frame.to_3d(np.asarray(_exterior(f.outline))) for f in b.faces]
        face = (0.55, 0.55, 0.55, 0.25) if b.support else (
            (0.9, 0.3, 0.2, 0.25) if b.id in unstable else (0.85, 0.8, 0.7, 0.18))
        ax.add_collection3d(Poly3DCollection(polys, facecolors=face,
                                             edgecolors=(0.3, 0.3, 0.3, 0.5), linewidths=0.4))
    all_pts = np.vstack([b.vertices for b in assembly.blocks])
    size = float(np.ptp(all_pts, axis=0).max())
    forces = [r.normal_forces for r in report.interfaces]
    fmax = max((np.abs(f).max(initial=0.0) for f in forces), default=0.0)
    scale = force_scale if force_scale else (0.1 * size / fmax if fmax > 0 else 0.0)
    comp_map, tens_map = plt.get_cmap("Blues"), plt.get_cmap("Reds")
    norm = colors.Normalize(0, fmax if fmax > 0 else 1.0)
    for r in report.interfaces:
        ring = np.vstack([r.polygon, r.polygon[:1]])
        ax.plot(*ring.T, color="goldenrod" if not (r.tension or r.friction_exceeded) else "crimson",
                linewidth=1.0)
        if len(r.kern):
            k = np.vstack([r.kern, r.kern[:1]])
            ax.plot(*k.T, color="darkgreen", linewidth=0.6, linestyle="--")
        segs, cols = [], []
        for p, fn, ft in zip(r.polygon, r.normal_forces, r.tangential_forces):
            f = fn * r.normal + ft
            segs.append([p, p - scale * f])          # drawn as the push of a on b, ending at p
            cmap = comp_map if fn >= 0 else tens_map
            cols.append(cmap(0.35 + 0.65 * norm(abs(fn))))
        ax.add_collection3d(Line3DCollection(segs, colors=cols, linewidths=2.0))
        if abs(r.normal_resultant) > 0:
            c = r.centre_of_pressure
            ax.plot(*np.array([c, c - scale * r.resultant / max(len(r.polygon), 1)]).T,
                    color="black", linewidth=1.2)
    lo, hi = all_pts.min(axis=0), all_pts.max(axis=0)
    centre, half = 0.5 * (lo + hi), 0.5 * size
    ax.set(xlim=(centre[0] - half, centre[0] + half), ylim=(centre[1] - half, centre[1] + half),
           zlim=(centre[2] - half, centre[2] + half),
           xlabel="x [m]", ylabel="y [m]", zlabel="z [m]")
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(*view)
    ax.set_title(title or report.message, fontsize=9)
    mappable = cm.ScalarMappable(norm=norm, cmap=comp_map)
    fig.colorbar(mappable, ax=ax, shrink=0.6, label="vertex compression [N] (red: tension)")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)
    return path


def _exterior(outline):
    geom = outline if outline.geom_type == "Polygon" else max(outline.geoms, key=lambda g: g.area)
    return list(geom.exterior.coords)
