"""Learning a style from one motion or several of one person (:mod:`.multi`): the NIO problem,
its initial θ, the optimiser, and the learned style with its provenance (clip, frames, body,
package versions, G, stop reason)."""
from __future__ import annotations

from dataclasses import replace
from typing import Sequence

from scenarios.versions import package_versions

from scenegraph.model.body import Character
from scenegraph.model.footsteps import Footstep
from scenegraph.model.motion import Motion
from scenegraph.model.style import Provenance, Style
from scenegraph.nio.bundle import run_bundle
from scenegraph.nio.multi import MultiNIO
from scenegraph.nio.problem import NIO
from scenegraph.nio.records import NIOResult
from scenegraph.nio.resynthesis import example_of
from scenegraph.nio.theta import style_from_theta

__all__ = ["learn_style", "learn_multi", "initial_style"]

PROVENANCE_PACKAGES = ("compose-motion", "casadi", "numpy")  # versions a learned style records


def initial_style(ch: Character, target: Motion, footsteps, **kw) -> Style:
    """The paper's initial style for ``target`` (:meth:`NIO.initial_theta`), not learned."""
    nio = NIO(ch, target, footsteps, **kw)
    return style_from_theta(nio.initial_theta(), name="nio-initial")


def learn_style(ch: Character, target: Motion, footsteps: tuple[Footstep, ...], **kw) -> NIOResult:
    """Learn a style from one motion ``target`` with its footsteps: :func:`learn_multi` with
    one clip (see there for the options)."""
    return learn_multi(ch, [(target, footsteps)], **kw)


def learn_multi(ch: Character, clips: Sequence[tuple[Motion, tuple[Footstep, ...]]], *, init: Style | str = "paper",
                name: str = "learned", clip: str | Sequence[str] | None = None,
                frames: str | Sequence[str] | None = None, body: str | None = None, callback=None,
                solve_iter: int = 100, cyclic: bool = False, local: bool = True, hessian: str = "gauss_newton",
                alpha_floor: float = 0.0, prior_weight: float = 0.0, tie: str = "none", alpha_ref: str = "uniform",
                spring_prior: float = 0.0, **run_kw) -> NIOResult:
    """Learn one style from the (target motion, footsteps) pairs ``clips`` of one person
    (:class:`.multi.MultiNIO`: Σ_c G_c + D).  ``init``: "paper" (α = 1/M, q̄ = mean pose,
    springs by Eq. 22 — of the first clip) or a Style to start from.  ``prior_weight``: the
    log-normal prior on α (:mod:`.prior`; 0: none); ``alpha_ref``: its centre, "uniform" (1/M)
    or "strength" (:func:`.prior.alpha_reference`; the initial α is then that reference too);
    ``spring_prior``: weight of the quadratic prior on ks1, ks2, kd around their Eq. 22 values
    (0: none); ``tie``: "none", "lr", "groups" or "coarse" (:func:`.prior.tie_pairs`; tied α keep
    the reference's ratios, tied springs the Eq. 22 fit's, :func:`.prior.tie_scales`); ``method``: "bundle" (default) or "gradient" (one clip).  ``clip`` / ``frames``: the clip file name(s) and "A:B" frame
    range(s), one per clip, for the provenance (the first is the style's ``clip``; with
    several all are listed under ``clips``).  The returned style carries its provenance and
    the example poses of the first clip; the result's ``nio`` is the first clip's NIO problem
    (for re-synthesis)."""
    from scenegraph.nio.prior import alpha_reference, tie_pairs, tie_scales
    from scenegraph.nio.theta import ALPHA, theta_scales

    if not clips:
        raise ValueError("learn_multi needs at least one clip")
    pairs = tie_pairs(tie)
    nios = [NIO(ch, target, footsteps, solve_iter=solve_iter, cyclic=cyclic, local=local, hessian=hessian,
                alpha_floor=alpha_floor) for target, footsteps in clips]
    prob = MultiNIO(nios)
    th0 = nios[0].initial_theta() if isinstance(init, str) else init.vector().copy()
    aref = alpha_reference(alpha_ref)
    if alpha_ref != "uniform":
        th0[ALPHA] = aref
    if local:  # cheap iterations (~1 s): a stricter relative-decrease stop
        run_kw.setdefault("rtol", 0.005)
        run_kw.setdefault("patience", 5)
    if prior_weight > 0 or pairs or spring_prior > 0:
        run_kw.update(prior_weight=prior_weight, ties=pairs, alpha_ref=aref, spring_weight=spring_prior,
                      tie_w=tie_scales(th0, aref, theta_scales(style_from_theta(th0))) if pairs else None)
    method = run_kw.pop("method", "bundle")
    if method == "gradient" and len(nios) == 1:  # the paper's step (one clip only)
        out = nios[0].run_gradient(th0, callback=callback, **run_kw)
    elif method == "bundle":
        out = run_bundle(prob, th0, callback=callback, **run_kw)
    else:
        raise ValueError(f"NIO method {method!r} is not available for {len(nios)} clip(s)")
    names = [clip] if clip is None or isinstance(clip, str) else list(clip)
    ranges = [frames] if frames is None or isinstance(frames, str) else list(frames)
    several = ({"clips": [{"clip": c, "frames": f} for c, f in zip(names, ranges)]} if len(names) > 1 else {})
    prov = Provenance(clip=names[0], frames=ranges[0], body=body or ch.preset,
                      versions=package_versions(PROVENANCE_PACKAGES, missing="unknown"), g_final=float(out.g_final),
                      g_initial=float(out.g_initial), iterations=out.iterations, stop=out.stop_reason,
                      counterexamples="local (one Gauss-Newton step from X_T)" if local else
                      f"spacetime solves of {solve_iter} IPOPT iterations",
                      **several,
                      **({"hessian": hessian} if hessian != "gauss_newton" else {}),
                      **({"alpha_floor": float(alpha_floor)} if alpha_floor > 0 else {}),
                      **({"alpha_prior": float(prior_weight)} if prior_weight > 0 else {}),
                      **({"tie": tie} if tie != "none" else {}),
                      **({"alpha_ref": alpha_ref} if alpha_ref != "uniform" else {}),
                      **({"spring_prior": float(spring_prior)} if spring_prior > 0 else {}))
    target, footsteps = clips[0]
    style = style_from_theta(out.theta, name=name, provenance=prov).with_(example=example_of(target, footsteps))
    return replace(out, style=style, nio=nios[0])
