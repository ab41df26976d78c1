"""The bpy-free core of the add-on: settings, marshalling of meshes to the library's arrays,
n-gon splitting, material maths, frame plans and display-subdivision grids.

Nothing here imports ``bpy``; everything is tested under plain Python (``tests/python/test_core_*``).
"""
