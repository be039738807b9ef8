"""``dsbrdf``: the Directional-Statistics BRDF as a Mitsuba BSDF.

XML (see :func:`mi_dsbrdf.model.library.material_from_params` for all forms)::

    <bsdf type="dsbrdf"/>                                   model mean material
    <bsdf type="dsbrdf"><string name="filename" value="material.json"/></bsdf>
    <bsdf type="dsbrdf"><string name="material" value="gold-metallic-paint"/></bsdf>
    <bsdf type="dsbrdf">
        <integer name="lobes" value="2"/>
        <string name="kappa_0" value="0.4"/> <string name="gamma_0" value="1"/>
        <string name="kappa_1" value="2 2 2.5 3 4 6"/> <string name="gamma_1" value="300"/>
        <string name="chromaticity_1" value="0.3 0.3 0.4"/>
    </bsdf>

Differentiable parameters (``mi.traverse``): ``log_kappa`` and ``log_gamma``
(R*6 spline control values, lobe-major) or, for a basis material, ``psi``
(k coefficients); and ``chromaticity`` (R*3, lobe-major); an update with a NaN
or the wrong number of values raises MaterialError. The formula and its
numerical guards are :func:`mi_dsbrdf.brdf.dsbrdf.lobe_rgb`; sampling is
:mod:`mi_dsbrdf.brdf.sampling`, with the mixture built from detached parameters so
that sampled directions do not depend on them.
"""
import drjit as dr
import mitsuba as mi

from mi_dsbrdf.brdf.angles import cos_half_diff, log_cos_h
from mi_dsbrdf.brdf.curves import N_CONTROL
from mi_dsbrdf.brdf.dsbrdf import clamp_controls, lobe_curves, lobe_rgb
from mi_dsbrdf.errors import MaterialError
from mi_dsbrdf.model.library import material_from_params
from mi_dsbrdf.brdf.sampling import dsbrdf_weights

from .common import both_above, pdf_of_mixture, sample_mixture

FLAGS = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide


class DSBRDF(mi.BSDF):
    def __init__(self, props):
        mi.BSDF.__init__(self, props)
        params = {k: props[k] for k in props.keys()}
        if "filename" in params:     # relative to the scene file's folder, like Mitsuba's own plugins
            params["filename"] = str(mi.file_resolver().resolve(params["filename"]))
        material, basis = material_from_params(params)
        self.material = material
        self.basis = basis
        self.knots = material.knots
        self.n_lobes = material.n_lobes
        if basis is not None:
            self.psi = mi.Float(material.psi)
        self.log_kappa = mi.Float(material.log_kappa.reshape(-1))
        self.log_gamma = mi.Float(material.log_gamma.reshape(-1))
        self.chromaticity = mi.Float(material.chromaticity.reshape(-1))
        self.m_flags = FLAGS
        self.m_components = [FLAGS]

    # --- parameters --------------------------------------------------------
    def traverse(self, callback):
        if self.basis is not None:
            callback.put("psi", self.psi, mi.ParamFlags.Differentiable)
        else:
            callback.put("log_kappa", self.log_kappa, mi.ParamFlags.Differentiable)
            callback.put("log_gamma", self.log_gamma, mi.ParamFlags.Differentiable)
        callback.put("chromaticity", self.chromaticity, mi.ParamFlags.Differentiable)

    def parameters_changed(self, keys):
        self._check_parameters()
        if self.basis is not None:
            # Eq. 2-3: control values = mean + sum_i psi_i b_i (keeps the AD graph to psi)
            ctrl = self.basis.control_values_dr(self.psi)
            idx_k = [r * 2 * N_CONTROL + j for r in range(self.n_lobes) for j in range(N_CONTROL)]
            self.log_kappa, self.log_gamma = clamp_controls(
                dr.gather(mi.Float, ctrl, mi.UInt32(idx_k)),
                dr.gather(mi.Float, ctrl, mi.UInt32([i + N_CONTROL for i in idx_k])))

    def _check_parameters(self):
        """MaterialError for a parameter set through ``mi.traverse`` with the wrong
        number of values or a NaN (which the evaluation's guards would otherwise
        clamp silently to a valid material)."""
        sizes = {"log_kappa": self.n_lobes * N_CONTROL, "log_gamma": self.n_lobes * N_CONTROL,
                 "chromaticity": self.n_lobes * 3}
        if self.basis is not None:
            sizes = {"psi": self.basis.n_bases, "chromaticity": self.n_lobes * 3}
        for name, size in sizes.items():
            value = getattr(self, name)
            if dr.width(value) != size:
                raise MaterialError("dsbrdf parameter %s needs %d values, got %d" % (name, size, dr.width(value)))
            nan = int(dr.count(dr.isnan(dr.detach(value)))[0])
            if nan:
                raise MaterialError("dsbrdf parameter %s has %d NaN value%s of %d: a material's parameters must be "
                                    "numbers" % (name, nan, "" if nan == 1 else "s", size))

    def _lobe_params(self, detach=False):
        def scalars(arr, width):
            arr = dr.detach(arr) if detach else arr
            return [[dr.gather(mi.Float, arr, r * width + j) for j in range(width)] for r in range(self.n_lobes)]
        return scalars(self.log_kappa, N_CONTROL), scalars(self.log_gamma, N_CONTROL), scalars(self.chromaticity, 3)

    # --- evaluation --------------------------------------------------------
    def _rho_cos(self, wi, wo):
        """Eq. 4 times cos theta_o, as a Color3f."""
        wi_t, wo_t = (wi.x, wi.y, wi.z), (wo.x, wo.y, wo.z)
        cos_h, cos_d, sin2_h = cos_half_diff(wi_t, wo_t)
        log_kappa, log_gamma, chroma = self._lobe_params()
        rgb = lobe_rgb(log_cos_h(cos_h, sin2_h), dr.safe_acos(cos_d), log_kappa, log_gamma, chroma, self.knots)
        return mi.Color3f(*rgb) * wo.z

    def _mixture(self, wi):
        """Sampling mixture for wi from detached lobe curves at theta_d = theta_i."""
        log_kappa, log_gamma, _ = self._lobe_params(detach=True)
        kappa, gamma = lobe_curves(dr.safe_acos(wi.z), log_kappa, log_gamma, self.knots)
        return dsbrdf_weights(kappa, gamma)

    def eval(self, ctx, si, wo, active=True):
        active = both_above(si, wo, active)
        return dr.select(active, self._rho_cos(si.wi, wo), 0.0)

    def pdf(self, ctx, si, wo, active=True):
        return pdf_of_mixture(si, wo, active, self._mixture(si.wi))

    def eval_pdf(self, ctx, si, wo, active=True):
        return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

    def sample(self, ctx, si, sample1, sample2, active=True):
        return sample_mixture(si, sample1, sample2, active, self._mixture(si.wi), self._rho_cos)

    def to_string(self):
        return "DSBRDF[lobes=%d, material=%s, basis=%s]" % (
            self.n_lobes, self.material.name, "yes" if self.basis is not None else "no")
