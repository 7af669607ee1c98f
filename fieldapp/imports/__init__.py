"""Bringing other people's data in: depth-image folders, RealSense recordings and point clouds.

Depth images and recordings become session folders (``fieldapp-session/1``) that
``fieldapp verify`` accepts; point clouds go straight to the plant and trait steps and become
a results folder (see ``docs/DATA.md``).
"""
