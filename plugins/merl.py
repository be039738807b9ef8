"""``merl``: a measured isotropic BRDF on the MERL grid as a Mitsuba BSDF.

The ground truth of the synthetic experiments. XML::

    <bsdf type="merl"><string name="filename" value="gold-metallic-paint.binary"/></bsdf>
    <bsdf type="merl">
        <string name="nbrdf" value=".../merl_nbrdf_weights.npz"/>
        <string name="material" value="gold-metallic-paint"/>
        <string name="interpolation" value="linear"/>   (or "nearest")
    </bsdf>

Lookup: :func:`mi_dsbrdf.measured.lookup_indices` (the table's own index
arithmetic); sampling: :mod:`mi_dsbrdf.sampling` with lobes fitted to the table
(:meth:`~mi_dsbrdf.measured.MeasuredBRDF.sampling_lobes`).
"""
import drjit as dr
import mitsuba as mi

from mi_dsbrdf.angles import half_diff
from mi_dsbrdf.errors import MeasuredFileError
from mi_dsbrdf.measured import MeasuredBRDF, lookup_indices
from mi_dsbrdf.sampling import mixture_pdf, mixture_sample

from .common import both_above, glossy_sample

FLAGS = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide


class MeasuredBSDF(mi.BSDF):
    def __init__(self, props):
        mi.BSDF.__init__(self, props)
        keys = set(props.keys())
        if "filename" in keys and "nbrdf" not in keys:
            brdf = MeasuredBRDF.from_binary(props["filename"])
        elif "nbrdf" in keys and "material" in keys and "filename" not in keys:
            brdf = MeasuredBRDF.from_nbrdf(props["nbrdf"], props["material"])
        else:
            raise MeasuredFileError("the merl BSDF needs either filename=<.binary> or nbrdf=<.npz> with "
                                    "material=<name>; got %s" % ", ".join(sorted(keys)))
        self.interpolation = props["interpolation"] if "interpolation" in keys else "linear"
        if self.interpolation not in ("linear", "nearest"):
            raise MeasuredFileError("interpolation must be 'linear' or 'nearest', got %r" % self.interpolation)
        self.name = brdf.name
        self.table = mi.Float(brdf.table.reshape(-1))
        self.w_cos, self.weights, self.exponents = brdf.sampling_lobes()
        self.m_flags = FLAGS
        self.m_components = [FLAGS]

    def traverse(self, callback):
        callback.put("table", self.table, mi.ParamFlags.NonDifferentiable)

    def parameters_changed(self, keys):
        pass

    def _rho_cos(self, wi, wo):
        th, _, td, pd = half_diff((wi.x, wi.y, wi.z), (wo.x, wo.y, wo.z))
        value = mi.Color3f(0.0)
        for idx, w in lookup_indices(th, td, pd, linear=self.interpolation == "linear"):
            value += dr.gather(mi.Color3f, self.table, mi.UInt32(idx)) * w
        return value * wo.z

    def eval(self, ctx, si, wo, active=True):
        return dr.select(both_above(si, wo, active), self._rho_cos(si.wi, wo), 0.0)

    def pdf(self, ctx, si, wo, active=True):
        pdf = mixture_pdf((si.wi.x, si.wi.y, si.wi.z), (wo.x, wo.y, wo.z), self.w_cos, self.weights, self.exponents)
        return dr.select(both_above(si, wo, active), pdf, 0.0)

    def eval_pdf(self, ctx, si, wo, active=True):
        return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

    def sample(self, ctx, si, sample1, sample2, active=True):
        wi = si.wi
        wi_t = (wi.x, wi.y, wi.z)
        wo_t, valid = mixture_sample(wi_t, sample1, sample2.x, sample2.y, self.w_cos, self.weights, self.exponents)
        wo = mi.Vector3f(*wo_t)
        pdf = mixture_pdf(wi_t, wo_t, self.w_cos, self.weights, self.exponents)
        active = active & valid & (pdf > 0) & (mi.Frame3f.cos_theta(wi) > 0)
        bs = glossy_sample(wo, pdf, active)
        return bs, dr.select(active, self._rho_cos(wi, wo) / dr.select(active, pdf, 1.0), 0.0)

    def to_string(self):
        return "MeasuredBSDF[%s, %s]" % (self.name, self.interpolation)
