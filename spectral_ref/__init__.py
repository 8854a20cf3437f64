"""spectral_ref: a compact, independent Fourier-spectral reference solver (model §2–§4, §6)."""

from .solver import SpectralBackend

__all__ = ["SpectralBackend"]
