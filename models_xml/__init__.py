"""MJCF assets shared by mjcodesign models (scene, ground, lights)."""

from pathlib import Path

ASSET_DIR = Path(__file__).parent
"""Folder that holds the XML assets."""
SCENE_XML = ASSET_DIR / "scene.xml"
"""Ground plane, light and visual settings."""

__all__ = ["ASSET_DIR", "SCENE_XML"]
