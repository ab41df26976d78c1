"""The native library (the C ABI of ``include/galerkin_radiosity.h``) through ctypes; bpy-free."""
