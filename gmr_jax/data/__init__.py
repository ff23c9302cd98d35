"""Data shipped with gmr_jax: the EMPS benchmark recordings (see `emps/README.md`)."""

from ._emps import (
    BENCHMARK_DECIMATION as EMPS_BENCHMARK_DECIMATION,
    DEFAULT_CUTOFF_HZ as EMPS_CUTOFF_HZ,
    REFERENCE as EMPS_REFERENCE,
    REFERENCE_ASYMMETRIC as EMPS_REFERENCE_ASYMMETRIC,
    REFERENCE_RELATIVE_ERROR as EMPS_REFERENCE_RELATIVE_ERROR,
    SAMPLE_TIME as EMPS_SAMPLE_TIME,
    emps_raw as emps_raw,
    load_emps as load_emps,
    lowpass_derivatives as lowpass_derivatives,
    parallel_decimate as parallel_decimate,
)

__all__ = ["EMPS_BENCHMARK_DECIMATION", "EMPS_CUTOFF_HZ", "EMPS_REFERENCE", "EMPS_REFERENCE_ASYMMETRIC",
           "EMPS_REFERENCE_RELATIVE_ERROR", "EMPS_SAMPLE_TIME", "emps_raw", "load_emps", "lowpass_derivatives",
           "parallel_decimate"]
