"""Records: the record type, loaders, validation, preprocessing and step segmentation."""

from workbench.records.record import G_M_S2, Record

__all__ = ["G_M_S2", "Record"]
