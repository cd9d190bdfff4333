"""``volprim_rf_dedup``: Mitsuba's ``volprim_rf_basic`` that composites a primitive once per entry.

Import only after a Mitsuba JIT variant is set (`splatbench.backends.builtins.mitsuba_scene.mitsuba_volprim`
does both). Dr.Jit's ``@dr.syntax`` rewrites `DedupVolprim.sample` against this
module's globals, hence a module of its own.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
from mitsuba.ad.integrators.volprim_rf_basic import BasicVolumetricPrimitiveRadianceFieldIntegrator


class DedupVolprim(BasicVolumetricPrimitiveRadianceFieldIntegrator):
    """``volprim_rf_basic`` that never composites one primitive twice in a row.

    Same kernel (the parent's ``eval_transmission`` and ``eval_sh_emission``), same ray
    advance (1e-4), same stopping rule (throughput <= 0.01, ``max_depth``), and the
    parent's PRB-style differential phase (used by `splatbench.backends` ``mitsuba``).
    The one change: a hit on the primitive that the previous step composited is stepped
    over. A ray enters a convex 3-sigma shell once, so such a hit is always the float32
    artefact described in `splatbench.validate.mitsuba`.
    """

    @dr.syntax
    def sample(self, mode, scene, sampler, ray, δL, state_in, active, **kwargs):  # noqa: N803
        primal = mode == dr.ADMode.Primal
        ray = mi.Ray3f(dr.detach(ray))
        active = mi.Bool(active)
        if not primal:  # If the gradient is zero, stop early
            active &= dr.any((δL != 0))
        depth = mi.UInt32(0)
        previous = mi.UInt32(0xFFFFFFFF)
        L = mi.Spectrum(0.0 if primal else state_in)  # radiance accumulator
        δL = mi.Spectrum(δL if δL is not None else 0)  # differential radiance
        throughput = mi.Spectrum(1.0)
        while dr.hint(active, label=f"Primitive splatting (dedup, {mode.name})"):
            si = scene.ray_intersect(ray, coherent=(depth == 0), ray_flags=mi.RayFlags.All, active=active)
            active &= si.is_valid() & si.shape.is_ellipsoids()
            fresh = active & (si.prim_index != previous)
            contribution = mi.Spectrum(0.0)
            with dr.resume_grad(when=not primal):
                emission = self.eval_sh_emission(si, ray, fresh)
                transmission = self.eval_transmission(si, ray, fresh)
                contribution[fresh] = throughput * (1.0 - transmission) * emission
                contribution[~dr.isfinite(contribution)] = 0.0
            L[fresh] = (L + contribution) if primal else (L - contribution)
            throughput[fresh] *= transmission
            with dr.resume_grad(when=not primal):
                if not primal:  # the parent's differential phase, for fresh hits only
                    reflected = L * transmission / dr.detach(transmission)
                    Lo = dr.select(fresh & dr.isfinite(contribution + reflected), contribution + reflected, 0.0)
                    if mode == dr.ADMode.Backward:
                        dr.backward_from(δL * Lo)
                    else:
                        δL += dr.forward_to(Lo)
            previous[active] = si.prim_index
            ray.o[active] = si.p + ray.d * 1e-4
            depth[active] += 1
            active &= dr.max(throughput) > 0.01
            active &= depth < self.max_depth
        if self.srgb_primitives:
            L = mi.math.srgb_to_linear(L)
        return L if primal else δL, True, [], L

    def to_string(self):
        return "DedupVolumetricPrimitiveRadianceFieldIntegrator[]"
