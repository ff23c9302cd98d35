"""Data shipped with gmr_jax: the EMPS benchmark recordings (see `emps/README.md`)."""

from ._emps import (
    REFERENCE as EMPS_REFERENCE,
    emps_raw as emps_raw,
    load_emps as load_emps,
    lowpass_derivatives as lowpass_derivatives,
    parallel_decimate as parallel_decimate,
)

__all__ = ["EMPS_REFERENCE", "emps_raw", "load_emps", "lowpass_derivatives", "parallel_decimate"]
