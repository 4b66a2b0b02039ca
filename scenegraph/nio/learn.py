"""Learning a style from one motion: the NIO problem, its initial θ, the optimiser, and the
learned style with its provenance (clip, frames, body, package versions, G, stop reason)."""
from __future__ import annotations

from dataclasses import replace

from scenarios.versions import package_versions

from scenegraph.model.body import Character
from scenegraph.model.footsteps import Footstep
from scenegraph.model.motion import Motion
from scenegraph.model.style import Provenance, Style
from scenegraph.nio.problem import NIO
from scenegraph.nio.records import NIOResult
from scenegraph.nio.resynthesis import example_of
from scenegraph.nio.theta import style_from_theta

__all__ = ["learn_style", "initial_style"]

PROVENANCE_PACKAGES = ("compose-motion", "casadi", "numpy")  # versions a learned style records


def initial_style(ch: Character, target: Motion, footsteps, **kw) -> Style:
    """The paper's initial style for ``target`` (:meth:`NIO.initial_theta`), not learned."""
    nio = NIO(ch, target, footsteps, **kw)
    return style_from_theta(nio.initial_theta(), name="nio-initial")


def learn_style(ch: Character, target: Motion, footsteps: tuple[Footstep, ...], *, init: Style | str = "paper",
                name: str = "learned", clip: str | None = None, frames: str | None = None,
                body: str | None = None, callback=None, solve_iter: int = 100, cyclic: bool = False,
                local: bool = True, hessian: str = "gauss_newton", alpha_floor: float = 0.0,
                prior_weight: float = 0.0, tie: str = "none", **run_kw) -> NIOResult:
    """Learn a style from ``target``.  ``init``: "paper" (α = 1/M, q̄ = mean pose, springs by
    Eq. 22) or a Style to start from.  ``prior_weight``: the log-normal prior on α
    (:mod:`.prior`; 0: none); ``tie``: "none", "lr" or "groups" (:func:`.prior.tie_pairs`).
    The returned style carries its provenance and the example poses of ``target``; the
    result's ``nio`` is the NIO problem (for re-synthesis)."""
    from scenegraph.nio.prior import tie_pairs

    pairs = tie_pairs(tie)
    nio = NIO(ch, target, footsteps, solve_iter=solve_iter, cyclic=cyclic, local=local, hessian=hessian,
              alpha_floor=alpha_floor)
    th0 = nio.initial_theta() if isinstance(init, str) else init.vector().copy()
    if local:  # cheap iterations (~1 s): a stricter relative-decrease stop
        run_kw.setdefault("rtol", 0.005)
        run_kw.setdefault("patience", 5)
    if prior_weight > 0 or pairs:
        run_kw.update(prior_weight=prior_weight, ties=pairs)
    out = nio.run(th0, callback=callback, **run_kw)
    prov = Provenance(clip=clip, frames=frames, body=body or ch.preset,
                      versions=package_versions(PROVENANCE_PACKAGES, missing="unknown"), g_final=float(out.g_final),
                      g_initial=float(out.g_initial), iterations=out.iterations, stop=out.stop_reason,
                      counterexamples="local (one Gauss-Newton step from X_T)" if local else
                      f"spacetime solves of {solve_iter} IPOPT iterations",
                      **({"hessian": hessian} if hessian != "gauss_newton" else {}),
                      **({"alpha_floor": float(alpha_floor)} if alpha_floor > 0 else {}),
                      **({"alpha_prior": float(prior_weight)} if prior_weight > 0 else {}),
                      **({"tie": tie} if tie != "none" else {}))
    style = style_from_theta(out.theta, name=name, provenance=prov).with_(example=example_of(target, footsteps))
    return replace(out, style=style, nio=nio)
