"""The plain-data contract between ``generator.usd`` and ``generator.render``.

``TranslatedScene`` (what a stage becomes, its shapes, emitters and instances typed records of
``scene_parts``), ``CameraTrack`` (a camera's time samples) and
``RenderPlan`` (what a scene's effects ask the renderer to simulate). NumPy and the standard
library only: both sides import these, and these import neither side.
"""
