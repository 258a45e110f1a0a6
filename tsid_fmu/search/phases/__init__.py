"""The MISO paper's contribution analyses and the phases they plan."""
