"""As-built checks: the declared pose uncertainty, and how sure a verdict is.

A verdict on measured poses rests on which face pairs count as contacts, and that is decided
by a tolerance (:mod:`rbe_ros.geometry.uncertainty`). Every report lists the *near contacts*
(face pairs beyond the tolerance but within NEAR_FACTOR times it) and says whether the
verdict is *sensitive* to the tolerance: whether the assembly would stand otherwise if the
near contacts were contacts, or if the contacts closest to the threshold (a gap beyond
MARGINAL_SHARE of their tolerance) were not. Each question costs one solve (the verdict
without its explanation, :func:`rbe_ros.analysis.verdict.is_stable`), asked only when such
face pairs exist: design geometry, whose gaps are rounding, asks neither.
"""
from __future__ import annotations

from dataclasses import replace

from ..geometry.contacts import Interface
from ..rbe.result import NearContact, Report, Status
from ..scene import Scene
from .assembly import Assembly
from .options import CheckOptions
from .verdict import is_stable

#: Contacts whose gap (or overlap) is beyond this share of their tolerance are the ones
#: closest to the threshold (dropped to test the verdict's sensitivity).
MARGINAL_SHARE = 0.8

#: Verdicts about the assembly's equilibrium (the others say nothing a tolerance could change).
_DECIDED = (Status.STABLE, Status.TENSION_REQUIRED, Status.FRICTION_EXCEEDED, Status.INFEASIBLE)


def declared(options: CheckOptions, scene: Scene) -> CheckOptions:
    """``options`` with the scene's declared pose uncertainty, unless the options declare
    one (a command-line option or node parameter wins over the scene file)."""
    if options.contact.uncertain or scene.pose_uncertainty is None:
        return options
    m, deg = scene.pose_uncertainty
    return replace(options, contact=replace(options.contact, pose_uncertainty_m=m,
                                            pose_uncertainty_deg=deg))


def sensitivity(report: Report, assembly: Assembly, options: CheckOptions
                ) -> tuple[tuple[NearContact, ...], str]:
    """The ``near_contacts`` of ``report`` (the check of ``assembly``) and, when its verdict
    is sensitive to the contact tolerance, why (else "")."""
    ids = [b.id for b in assembly.blocks]
    near = tuple(NearContact(ids[it.a], ids[it.b], it.gap, it.area) for it in assembly.near)
    if report.status not in _DECIDED:
        return near, ""
    stood = report.stable
    why = []
    if assembly.near:
        if is_stable(replace(assembly, interfaces=assembly.interfaces + assembly.near, near=()),
                     options) != stood:
            why.append(f"with the near contact{'s' * (len(assembly.near) > 1)} "
                       f"{_pairs(assembly.near, ids)} it would {_verb(not stood)}")
    marginal = [it for it in assembly.interfaces if abs(it.gap) > MARGINAL_SHARE * it.tol]
    if marginal:
        kept = tuple(it for it in assembly.interfaces if abs(it.gap) <= MARGINAL_SHARE * it.tol)
        if is_stable(replace(assembly, interfaces=kept), options) != stood:
            why.append(f"without the contact{'s' * (len(marginal) > 1)} "
                       f"{_pairs(marginal, ids)}, near the tolerance, it would "
                       f"{_verb(not stood)}")
    return near, "; ".join(why)


def _verb(stand: bool) -> str:
    return "stand" if stand else "not stand"


def _pairs(interfaces: list[Interface], ids: list[str], shown: int = 3) -> str:
    """"a|b (gap 1.2 mm of 0.9 allowed), ..." for the first ``shown`` of ``interfaces``."""
    text = ", ".join(f"{ids[it.a]}|{ids[it.b]} ({'gap' if it.gap >= 0 else 'overlap'} "
                     f"{1e3 * abs(it.gap):.3g} mm, tolerance {1e3 * it.tol:.3g} mm)"
                     for it in interfaces[:shown])
    return text + (f" and {len(interfaces) - shown} more" if len(interfaces) > shown else "")
