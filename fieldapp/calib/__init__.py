"""Calibration solvers (Qt-free): intrinsics, view-to-view, station-to-station, ground."""
