"""Shared fixtures for the Python suite.

bpy-free tests (``test_core_*``) import ``addon.core`` directly. Blender tests take the
``blender`` fixture: bpy imported once per process (with BLENDER_USER_RESOURCES in a temporary
folder), the add-on registered from the checkout, and a factory-empty file per test (classes
registered directly survive ``read_factory_settings``).
"""

import os
import sys
import tempfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
TESTS = Path(__file__).resolve().parent
for p in (str(REPO), str(TESTS)):
    if p not in sys.path:
        sys.path.insert(0, p)


@pytest.fixture(scope="session")
def bpy_module():
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="blender-user-"))
    import bpy

    import addon

    addon.register()
    yield bpy
    addon.unregister()


@pytest.fixture
def blender(bpy_module):
    bpy = bpy_module
    bpy.ops.wm.read_factory_settings(use_empty=True)
    from addon.blender import bake

    bake.drop_held()
    bake.listeners.clear()
    yield bpy
    bake.listeners.clear()
    if bpy.context.scene is not None and bpy.context.scene.radiosity.live_preview:
        bpy.context.scene.radiosity.live_preview = False
