"""``merl``: a measured isotropic BRDF on the MERL grid as a Mitsuba BSDF.

The ground truth of the synthetic experiments. XML::

    <bsdf type="merl"><string name="filename" value="gold-metallic-paint.binary"/></bsdf>
    <bsdf type="merl">
        <string name="nbrdf" value=".../merl_nbrdf_weights.npz"/>
        <string name="material" value="gold-metallic-paint"/>
        <string name="interpolation" value="linear"/>   (or "nearest")
    </bsdf>

Lookup: :func:`mi_dsbrdf.brdf.measured.lookup_indices` (the table's own index
arithmetic); sampling: :mod:`mi_dsbrdf.brdf.sampling` with lobes fitted to the table
(:meth:`~mi_dsbrdf.brdf.measured.MeasuredBRDF.sampling_lobes`).
"""
import drjit as dr
import mitsuba as mi

from mi_dsbrdf.brdf.angles import half_diff
from mi_dsbrdf.errors import MeasuredFileError
from mi_dsbrdf.brdf.measured import MeasuredBRDF, is_linear, lookup_indices

from .common import both_above, pdf_of_mixture, sample_mixture

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
        self.linear = is_linear(self.interpolation)
        self.name = brdf.name
        self.table = mi.Float(brdf.table.reshape(-1))
        self.mixture = brdf.sampling_lobes()
        self.m_flags = FLAGS
        self.m_components = [FLAGS]

    def traverse(self, callback):
        callback.put("table", self.table, mi.ParamFlags.NonDifferentiable)

    def parameters_changed(self, keys):
        pass

    def _rho_cos(self, wi, wo):
        th, _, td, pd = half_diff((wi.x, wi.y, wi.z), (wo.x, wo.y, wo.z))
        value = mi.Color3f(0.0)
        for idx, w in lookup_indices(th, td, pd, linear=self.linear):
            value += dr.gather(mi.Color3f, self.table, mi.UInt32(idx)) * w
        return value * wo.z

    def eval(self, ctx, si, wo, active=True):
        return dr.select(both_above(si, wo, active), self._rho_cos(si.wi, wo), 0.0)

    def pdf(self, ctx, si, wo, active=True):
        return pdf_of_mixture(si, wo, active, self.mixture)

    def eval_pdf(self, ctx, si, wo, active=True):
        return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

    def sample(self, ctx, si, sample1, sample2, active=True):
        return sample_mixture(si, sample1, sample2, active, self.mixture, self._rho_cos)

    def to_string(self):
        return "MeasuredBSDF[%s, %s]" % (self.name, self.interpolation)
