"""The learned reflectance model (paper Sec. 3): fits of measured BRDFs (Eq. 5), FPCA
bases, the GMM and hue priors (Eq. 6-12), the material library and the model file."""
