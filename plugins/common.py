"""Glue shared by the BSDF plugins (Mitsuba types only; no model code)."""
import drjit as dr
import mitsuba as mi


def both_above(si, wo, active):
    """Mask of reflection configurations: wi and wo above the surface."""
    return active & (mi.Frame3f.cos_theta(si.wi) > 0) & (mi.Frame3f.cos_theta(wo) > 0)


def glossy_sample(wo, pdf, active):
    """A BSDFSample3f for a sampled glossy reflection (pdf 0 where inactive)."""
    bs = dr.zeros(mi.BSDFSample3f)
    bs.wo = wo
    bs.pdf = dr.select(active, pdf, 0.0)
    bs.eta = 1.0
    bs.sampled_type = mi.UInt32(+mi.BSDFFlags.GlossyReflection)
    bs.sampled_component = mi.UInt32(0)
    return bs
