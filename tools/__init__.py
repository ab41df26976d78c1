"""Validation, demo and plotting tools that drive Blender (bpy) and the add-on."""
