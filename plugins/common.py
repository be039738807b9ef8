"""Glue shared by the BSDF plugins: Mitsuba types around the library's
sampling mixture (:mod:`mi_dsbrdf.brdf.sampling`); no model code."""
import drjit as dr
import mitsuba as mi

from mi_dsbrdf.brdf.sampling import mixture_pdf, mixture_sample


def both_above(si, wo, active):
    """Mask of reflection configurations: wi and wo above the surface."""
    return active & (mi.Frame3f.cos_theta(si.wi) > 0) & (mi.Frame3f.cos_theta(wo) > 0)


def _tuple(v):
    return (v.x, v.y, v.z)


def pdf_of_mixture(si, wo, active, mixture):
    """``BSDF.pdf`` for a mixture ``(w_cos, weights, exponents)``."""
    pdf = mixture_pdf(_tuple(si.wi), _tuple(wo), *mixture)
    return dr.select(both_above(si, wo, active), pdf, 0.0)


def sample_mixture(si, sample1, sample2, active, mixture, rho_cos):
    """``BSDF.sample`` for a mixture ``(w_cos, weights, exponents)``.

    ``rho_cos(wi, wo)``: the BSDF value times cos theta_o (Color3f). Returns
    ``(BSDFSample3f, weight)`` with weight = rho_cos / pdf, 0 for invalid samples.
    """
    wi_t = _tuple(si.wi)
    wo_t, valid = mixture_sample(wi_t, sample1, sample2.x, sample2.y, *mixture)
    wo = mi.Vector3f(*wo_t)
    pdf = mixture_pdf(wi_t, wo_t, *mixture)
    active = active & valid & (pdf > 0) & (mi.Frame3f.cos_theta(si.wi) > 0)
    bs = dr.zeros(mi.BSDFSample3f)
    bs.wo = wo
    bs.pdf = dr.select(active, pdf, 0.0)
    bs.eta = 1.0
    bs.sampled_type = mi.UInt32(+mi.BSDFFlags.GlossyReflection)
    bs.sampled_component = mi.UInt32(0)
    weight = rho_cos(si.wi, wo) / dr.select(active, pdf, 1.0)
    return bs, dr.select(active, weight, 0.0)
