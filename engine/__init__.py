"""The buildingparser engine: the algorithms of Armeni et al. (CVPR 2016) as a dask pipeline.

Data flows one way: tiles -> spaces -> canonical frames -> detections -> CRF -> outputs and metrics.
"""
import engine.config  # noqa: F401  (registers the dask.config defaults)
