"""OpenUSD stages to the plain-data contract (``generator.contract``), with pxr and nothing of Mitsuba.

``translate.translate_usd`` is the entry point; the other modules each read one kind of prim
(camera, geometry, lights, materials, textures) or add what a user's stage lacks (``additions``).
pxr is imported inside the functions that need it, so that importing this package is cheap.
"""
