"""Reflectance and illumination recovery from one image (paper Sec. 4-5): forward model, posterior, blocks, drivers."""
