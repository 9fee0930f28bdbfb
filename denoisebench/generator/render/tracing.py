"""What the surface and the volumetric tracers share: their compile-time switches, the scene probes
that set them, the start of every sample (the camera ray) and the first vertex's questions to its BSDF.

:class:`KernelOptions` holds the switches (each combination compiles once); ``scene_has_*`` read them
off a Mitsuba scene. :func:`camera_ray` draws a sample's sub-pixel offset, shutter time and lens point
in that fixed order, so that :mod:`~denoisebench.generator.render.integrator` and
:mod:`~denoisebench.generator.render.volpath` consume the same random numbers for the same camera ray.
:func:`first_vertex_bsdf` evaluates, samples and reads the features of a BSDF in one dynamic dispatch;
:func:`mis_weight` is Mitsuba's power heuristic; :func:`previous_point` is where a hit point was one
frame earlier (the ``vertex_prev_position`` attribute of moving meshes, render/scene.py).

Pitfall: changing the draw order of :func:`camera_ray` changes every image's bytes (and the per-sample
``pixel``, ``time`` and ``lens`` channels it writes).
"""

from __future__ import annotations

from dataclasses import dataclass

from denoisebench.generator.contract.render_plan import UNBOUNDED_DEPTH, paths_bounce
from denoisebench.generator.render.camera import DrCamera
from denoisebench.generator.render.scene import PREVIOUS_POSITION


@dataclass(frozen=True)
class KernelOptions:
    """Compile-time switches of the kernel (each combination compiles once and is cached)."""

    max_depth: int
    rr_depth: int
    lobe_split: bool
    features: bool  # False: color / diffuse / specular only (reference renders)
    motion: bool
    follow_delta_albedo: bool  # the scene has delta-only BSDFs: continue the albedo through them
    jitter: bool = True  # False: every sample at the pixel center (tests compare with Mitsuba's aov)
    # Per-sample data for RPF: the first vertex's light and bounce random numbers and the second hit
    second_hit: bool = False
    object_motion: bool = False  # meshes carry vertex_prev_position: motion follows moving objects
    null_skips: int = (
        0  # cut-outs (mask BSDFs): fully transparent surfaces the camera ray passes before its first vertex
    )
    media: bool = False  # the scene has participating media: trace with render/volpath.py (else never entered)

    @property
    def bounded(self) -> bool:
        """False for ``max_depth == -1`` (unbounded: no depth test in the loop at all)."""
        return self.max_depth != UNBOUNDED_DEPTH

    @property
    def bounces(self) -> bool:
        """Paths go past the camera's first hit (next-event estimation and BSDF sampling happen)."""
        return paths_bounce(self.max_depth)


def mis_weight(dr, pdf_a, pdf_b):
    """Power heuristic, as Mitsuba's ``path`` (zero where it is not finite)."""
    a2 = dr.square(pdf_a)
    w = a2 / (a2 + dr.square(pdf_b))
    return dr.select(dr.isfinite(w), w, 0.0)


def scene_has_delta_only_bsdf(mi, scene) -> bool:
    """True when some shape's BSDF has no smooth lobe (mirror, glass): albedo must look through it."""
    for shape in scene.shapes():
        bsdf = shape.bsdf()
        if bsdf is None:
            continue
        flags = bsdf.flags()
        if not mi.has_flag(flags, mi.BSDFFlags.Smooth):
            return True
    return False


def _diffuse_part(mi, bsdf, ctx_diffuse, si, wo, val, active):
    """The diffuse lobes' share of ``val`` (the full BSDF value): a second evaluation only when needed.

    Notes
    -----
    Inside :func:`drjit.dispatch` ``bsdf`` is one concrete instance, so its lobe flags are known
    while the kernel is traced. A BSDF whose lobes are all diffuse (``diffuse``, ``twosided``
    diffuse) has ``val`` as its diffuse part, one without diffuse lobes (conductors, dielectrics)
    has 0: both are exactly what the Diffuse-masked evaluation returns, without paying for it.
    Only mixed BSDFs (principled, plastics) evaluate twice.
    """
    # Lobe bits only (BSDFFlags.All also holds Anisotropic, Delta1D, ...).
    lobes = int(bsdf.flags()) & int(mi.BSDFFlags.Diffuse | mi.BSDFFlags.Glossy | mi.BSDFFlags.Delta)
    diffuse = int(mi.BSDFFlags.Diffuse)
    if lobes & diffuse == 0:
        return mi.Color3f(0.0)
    if lobes & ~diffuse == 0:
        return mi.Color3f(val)
    return bsdf.eval(ctx_diffuse, si, wo, active)


#: Fully transparent cut-out layers a camera ray passes through before its first vertex (scenes with masks).
NULL_SKIPS = 4


def scene_has_null_bsdf(mi, scene) -> bool:
    """True when some shape's BSDF has a null (pass-through) lobe: an opacity mask (cut-out)."""
    return any(
        shape.bsdf() is not None and mi.has_flag(shape.bsdf().flags(), mi.BSDFFlags.Null) for shape in scene.shapes()
    )


def scene_has_object_motion(scene) -> bool:
    """True when the scene's meshes carry previous-frame positions (a scene with moving objects)."""
    return any(shape.is_mesh() and bool(shape.has_attribute(PREVIOUS_POSITION)) for shape in scene.shapes())


def previous_point(shape, si, active):
    """Where the hit point was one frame earlier (one concrete shape inside :func:`drjit.dispatch`)."""
    import mitsuba as mi

    if shape.is_mesh() and bool(shape.has_attribute(PREVIOUS_POSITION)):
        return mi.Point3f(shape.eval_attribute_3(PREVIOUS_POSITION, si, active))
    return mi.Point3f(si.p)


def first_vertex_bsdf(split, want_features, bsdf, ctx, ctx_diffuse, si, wo, sample1, sample2, active_em, active):
    """Everything the first vertex asks of its BSDF, in one dynamic dispatch per BSDF instance."""
    import drjit as dr
    import mitsuba as mi

    val, pdf, bs, weight = bsdf.eval_pdf_sample(ctx, si, wo, sample1, sample2, active)
    val_diffuse = _diffuse_part(mi, bsdf, ctx_diffuse, si, wo, val, active_em) if split else mi.Color3f(0.0)
    if want_features:
        flags = bsdf.flags()
        if mi.has_flag(flags, mi.BSDFFlags.Diffuse):
            albedo = bsdf.eval_diffuse_reflectance(si, active)
        else:
            # No diffuse lobe (rough conductor, rough dielectric): Mitsuba's default
            # eval_diffuse_reflectance is pi * f(wi, n), which a narrow lobe makes >> 1. The sampled
            # weight f cos / pdf is an unbiased one-sample estimate of the directional albedo instead.
            albedo = mi.Color3f(weight)
        if bsdf.has_attribute("roughness"):
            rough = bsdf.eval_attribute_1("roughness", si, active)
        elif bsdf.has_attribute("alpha"):
            rough = dr.sqrt(dr.maximum(bsdf.eval_attribute_1("alpha", si, active), 0.0))
        elif bsdf.has_attribute("alpha_u"):
            au = dr.maximum(bsdf.eval_attribute_1("alpha_u", si, active), 0.0)
            av = dr.maximum(bsdf.eval_attribute_1("alpha_v", si, active), 0.0)
            rough = dr.sqrt(0.5 * (au + av))
        elif (
            mi.has_flag(flags, mi.BSDFFlags.Diffuse)
            and not mi.has_flag(flags, mi.BSDFFlags.Glossy)
            and not mi.has_flag(flags, mi.BSDFFlags.Delta)
        ):
            rough = mi.Float(1.0)
        else:
            rough = mi.Float(0.0)
    else:
        albedo = mi.Color3f(0.0)
        rough = mi.Float(0.0)
    return val, pdf, bs, weight, val_diffuse, albedo, rough


def camera_ray(mi, sampler, camera: DrCamera, opts: KernelOptions, pixel_x, pixel_y, out: dict):
    """(film position, time, camera ray, camera pose) of one sample per lane; its random parameters go to ``out``.

    Draws, in this order: the sub-pixel offset (2, or the pixel centre without jitter), the shutter
    time (1, only with time sampling), the lens point (2, only with a thin lens): the start of every
    tracer's fixed random-number order (``integrator.trace``, ``volpath.trace``)."""
    switches = camera.switches
    if opts.jitter:
        offset = sampler.next_2d()
    else:
        offset = mi.Point2f(0.5, 0.5)
    film = mi.Point2f(mi.Float(pixel_x) + offset.x, mi.Float(pixel_y) + offset.y)
    out["pixel"] = offset
    if switches.time_sampling:
        shutter = sampler.next_1d()
        time = camera.sample_time(shutter)
        out["time"] = shutter
    else:
        time = camera.frame_time + mi.Float(0.0) * film.x  # per-lane array
    if switches.thin_lens:
        lens_uv = sampler.next_2d()
        out["lens"] = lens_uv
    else:
        lens_uv = None
    ray, pose = camera.generate_ray(film, lens_uv, time)
    return film, time, ray, pose
