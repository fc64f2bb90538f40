"""Wavelet multi-resolution split of signals into low- and high-frequency parts."""

from cdpr_pipeline.wavelet.split import WaveletSplit, band_energies

__all__ = ["WaveletSplit", "band_energies"]
