"""Scenes to dataset frames: USD translation, the render plan, the feature renderer, the dataset run.

Subpackages by concern, with one-way imports (``tests/test_architecture.py`` holds them):

``contract``
    Plain data between the two sides: the translated scene, the camera track, the render plan.
    Imports neither pxr nor Mitsuba.
``usd``
    OpenUSD (pxr) only: stage, camera, geometry, lights, materials, textures, additions (auto
    camera, default lights), effects inference, and ``translate`` (stage → ``TranslatedScene``).
    Never imports ``render``.
``render``
    Mitsuba and Dr.Jit only: scene building, camera rays, the feature integrator, frame rendering,
    adaptive references. Never imports ``usd``.

Beside them, the production side: ``dataset_run`` (one ``generate-dataset`` run),
``dataset_scenes`` (scene specs and the stage copies a run renders), ``frame_jobs`` (a frame's
render job and its per-process stage cache), ``executors`` (local and Ray), ``preview``, and
``image_codec`` (texture decoding, the one place the USD side needs Mitsuba's image reader).
"""
