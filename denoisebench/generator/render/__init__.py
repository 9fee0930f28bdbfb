"""Mitsuba 3 and Dr.Jit: the contract's scenes and plans into images and feature buffers.

``scene`` builds the Mitsuba scene, ``camera`` generates rays (pinhole, thin lens, shutter),
``integrator`` traces paths and records features, ``frame`` renders one frame's buffers and
``reference`` renders adaptive references. Mitsuba is loaded through ``mitsuba_runtime`` (which
picks the variant and libLLVM) when the first frame is rendered, not when this package is imported.
"""
