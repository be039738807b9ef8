"""The DSBRDF and measured BRDFs: angles, kappa/gamma curves (Eq. 2-3), the lobe
formula (Eq. 4), chromaticity, sampling, the MERL table."""
