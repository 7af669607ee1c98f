"""Standard exports of results: LAZ 1.4 and PLY clouds with per-point plant ids, a MIAPPE
ISA-Tab bundle, BrAPI v2 JSON and CSVs with units (``fieldapp export``, ``docs/DATA.md``)."""
