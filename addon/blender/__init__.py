"""The Blender-facing layer: export from the evaluated depsgraph, colour attributes, the
Geometry Nodes switch, the bake job and the live-preview handlers. Imported lazily by the
operators, so registering the add-on stays cheap."""
