"""The feature path tracer: one Dr.Jit kernel yields color, the lobe split and every feature per sample.

The estimator is Mitsuba 3's ``path`` integrator (``src/integrators/path.cpp``) written in Python:
next-event estimation at every non-delta vertex, BSDF sampling to continue, both combined by multiple
importance sampling with the power heuristic; Russian roulette from ``rr_depth`` with Mitsuba's
survival probability ``min(max(throughput) * eta^2, 0.95)``; ``max_depth`` in Mitsuba's convention
(1: only emitters seen directly, 2: direct lighting, ..., -1: unbounded, which Mitsuba stores as
``(uint32) -1`` and we express by dropping the depth test, so paths end only by Russian roulette, by
escaping, or at zero throughput). It is therefore an unbiased estimator of
the very image ``path`` renders at the same ``max_depth`` (tests/generator/render/test_features.py checks
this statistically).

The first vertex is peeled out of the bounce loop: it is where the features are read and where the
lobe split is decided, and peeling keeps that work out of the loop body that all later bounces run.

Lobe split (``diffuse + specular = color`` per sample, exactly up to float rounding):

* emission seen directly by the camera goes to **diffuse**;
* next-event estimation at the first vertex is split by BSDF lobe: the diffuse part is the BSDF
  evaluated with ``BSDFContext.type_mask = Diffuse`` (diffuse reflection and transmission), the
  specular part is the full evaluation minus it; both carry the same MIS weight;
* everything gathered after the first bounce goes to the buffer of the lobe *sampled* at the first
  vertex (``bs.sampled_type`` has a Diffuse flag → diffuse, else → specular; glossy, delta and null
  lobes count as specular).

Features (the first vertex is the camera ray's first intersection):

* ``normal``: world-space shading normal ``si.sh_frame.n`` at the first hit;
* ``position``: world-space first-hit position; ``depth``: its camera-space depth along the view
  axis (from the lens center, at the ray's camera pose);
* ``roughness``: first-hit roughness: the BSDF's ``roughness`` attribute when it has one (principled),
  else ``sqrt(alpha)`` of microfacet BSDFs (so that it matches principled's perceptual roughness),
  else 1 for purely diffuse BSDFs and 0 for anything else (smooth conductors, dielectrics);
* ``albedo``: ``bsdf.eval_diffuse_reflectance`` at the first non-delta hit (for BSDFs without a
  diffuse lobe, the BSDF sample weight: a one-sample estimate of the directional albedo); when the camera ray first
  meets delta surfaces (mirror, glass) the path is followed through them and the albedo is the
  throughput of that delta chain times the diffuse reflectance where it ends (0 if it escapes);
* the first hit skips up to :data:`NULL_SKIPS` fully transparent cut-out points (opacity masks):
  features, motion and the first vertex belong to the surface seen through the hole;
* ``motion``: the first-hit point projected through the pinhole (lens center) of the camera one frame
  earlier than the ray's time, minus its projection at the ray's time (pixels, x right, y down).
  With ``KernelOptions.object_motion`` (scenes with moving objects) the point projected into the
  previous frame is where the hit surface point *was* one frame earlier: the mesh attribute
  ``vertex_prev_position`` (render/scene.py) interpolated at the hit, exact for rigid and for
  per-vertex motion alike (both are affine within a triangle); analytic shapes are static.
  A first hit on a shape that moves *within* the shutter (:mod:`~denoisebench.generator.render.motion`)
  has its motion defined at the shutter's centre instead (object and camera at ``t_c - 1`` and ``t_c``).

Object motion blur: given a :class:`~denoisebench.generator.render.motion.ShutterMotionScene`, every
intersection and shadow test (camera ray, cut-out skips, bounces, next-event estimation, second hit)
also meets the moving shapes at the ray's time; features are those of each sample's own hit. For a
plain ``mi.Scene`` the kernel is the same code as before (same bytes).

With ``KernelOptions.second_hit`` (per-sample data only; paths that bounce) a sample also carries
what Sen & Darabi's random parameter filter analyses: ``light`` (the 2-D random numbers of the
first vertex's light sample), ``bounce`` (the 2-D random numbers that chose the first bounce's
direction: ``sample2`` of ``bsdf.sample``) and ``position2``/``normal2`` (world-space point and
shading normal where that bounce ray lands; 0 where it misses or the path ends at the first hit).
The second hit costs one more intersection per sample; the path itself draws the same random numbers
with or without these channels, so the image is the same bytes.

Background (miss) convention: color is the environment's radiance (0 without one); albedo, normal,
depth, position and roughness are 0; motion reprojects the ray *direction* (a point at infinity, so
rotation only). Points behind either camera get zero motion. At frame 0 there is no previous
frame and motion is 0. Everything is finite.

What this tracer shares with the volumetric one (switches, camera ray, first-vertex BSDF queries) is in
:mod:`~denoisebench.generator.render.tracing`; the loop that runs it over a pixel's samples and keeps
per-pixel moments is :mod:`~denoisebench.generator.render.moments`.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

from denoisebench.generator.render.camera import DrCamera
from denoisebench.generator.render.motion import NO_OBJECT, ShutterMotionScene
from denoisebench.generator.render.tracing import (
    KernelOptions,
    camera_ray,
    first_vertex_bsdf,
    mis_weight,
    previous_point,
)


@dataclass
class _PreviousVertex:
    """The vertex a ray leaves from, as the next hit's MIS weight needs it (a Dr.Jit PyTree: loop state).

    ``p``, ``n``: position and geometric normal; ``pdf``: the solid-angle density with which the BSDF
    sampled the ray; ``delta``: the sampled lobe was a delta lobe (no emitter sampling could have
    produced the direction, so an emitter it hits has MIS weight 1).
    """

    p: object
    n: object
    pdf: object
    delta: object

    @classmethod
    def of(cls, mi, si, bs):
        """The vertex at ``si`` whose BSDF sample ``bs`` spawned the next ray (fresh copies: loop state)."""
        return cls(
            p=mi.Point3f(si.p),
            n=mi.Normal3f(si.n),
            pdf=mi.Float(bs.pdf),
            delta=mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta),
        )


@dataclass
class _DeltaAlbedo:
    """The albedo feature of a camera path that first meets delta surfaces (mirror, glass).

    ``pending`` is True while the path has seen only delta surfaces and has not escaped; at the first
    smooth hit ``albedo`` becomes the throughput times that surface's diffuse reflectance and
    ``pending`` turns False (it stays 0 where the chain escapes or the path ends).
    """

    albedo: object
    pending: object


@dataclass
class _PathState:
    """The bounce loop's state: one path per lane past its first vertex (a Dr.Jit PyTree).

    Attributes
    ----------
    sampler : SampleStream
        The lane's random stream (a ``DRJIT_STRUCT``; its PCG32 state advances in the loop).
    ray : mi.Ray3f
        The ray the next iteration traces.
    beta : mi.Spectrum
        Path throughput up to ``ray``'s origin, Russian-roulette weights included.
    eta : mi.Float
        Product of the relative indices of refraction sampled so far (Mitsuba's roulette uses it).
    depth : mi.UInt32
        Vertices so far (Mitsuba's ``depth``: 1 after the first hit).
    radiance : mi.Color3f
        Light gathered past the first vertex (emission the bounces hit, next-event estimation at
        later vertices); ``trace`` gives it to the lobe sampled at the first vertex.
    prev : _PreviousVertex
        Where ``ray`` leaves from.
    active : mi.Bool
        The lane's path goes on.
    delta_albedo : _DeltaAlbedo or None
        The delta-chain albedo, only when it is followed (``KernelOptions.follow_delta_albedo`` and
        features); None otherwise.

    Notes
    -----
    ``delta_albedo`` is a field only when followed because an unchanging loop variable makes Dr.Jit
    record the loop body twice (loop-invariant detection). Fields are traversed in declaration order.
    """

    sampler: object
    ray: object
    beta: object
    eta: object
    depth: object
    radiance: object
    prev: _PreviousVertex
    active: object
    delta_albedo: _DeltaAlbedo | None = None

    def roulette(self, rr_depth: int, active_next) -> None:
        """Russian roulette after a vertex: reweight ``beta`` and decide ``active`` from ``active_next``.

        From depth ``rr_depth`` on, a path survives with Mitsuba's probability
        ``min(max(beta) * eta^2, 0.95)`` and is divided by it; below that depth it always survives.
        A path of zero throughput ends either way.

        Notes
        -----
        It draws one number from ``sampler`` on every lane, whether roulette applies there or not,
        so the random stream (and the image bytes) never depend on depth or throughput.
        """
        import drjit as dr

        beta_max = dr.max(self.beta)
        rr_prob = dr.minimum(beta_max * dr.square(self.eta), 0.95)
        rr_active = self.depth >= rr_depth
        rr_continue = self.sampler.next_1d() < rr_prob
        self.beta = dr.select(rr_active, self.beta * dr.rcp(rr_prob), self.beta)
        self.active = active_next & (~rr_active | rr_continue) & (beta_max != 0.0)


def _bounce(mi, scene, motion, poses, ctx, opts: KernelOptions, state: _PathState):
    """One iteration of the bounce loop: the vertex ``state.ray`` hits, and the ray it sends on.

    In order: the emission the ray hits (MIS against the emitter sampling at ``state.prev``), the
    delta-chain albedo when followed, next-event estimation, the BSDF sample that spawns the next
    ray, then :meth:`_PathState.roulette`. ``motion`` (a ``MovingShapes`` or None) with ``poses`` adds
    the shapes that move within the shutter to every intersection and shadow test.

    Notes
    -----
    Random numbers per iteration, in order: emitter sample (2), BSDF sample (1 + 2), roulette (1).
    Returns a one-tuple, the shape of ``dr.while_loop``'s state.
    """
    import drjit as dr

    ray, beta, prev, active = state.ray, state.beta, state.prev, state.active
    sampler = state.sampler
    if motion is None:
        si = scene.ray_intersect(ray, mi.RayFlags.All, False, active)
    else:
        si = motion.ray_intersect(scene, ray, False, active, poses)[0]
    prev_si = mi.Interaction3f(dr.zeros(mi.Float), ray.time, mi.Color0f(), prev.p, prev.n)
    ds = mi.DirectionSample3f(scene, si, prev_si)
    em_pdf = scene.pdf_emitter_direction(prev_si, ds, active & ~prev.delta)
    mis = mis_weight(dr, prev.pdf, em_pdf)
    emitted = ds.emitter.eval(si, active & (prev.pdf > 0.0))
    radiance = dr.select(active, state.radiance + beta * mis * emitted, state.radiance)

    active_next = active & si.is_valid()
    if opts.bounded:
        active_next &= state.depth + 1 < opts.max_depth
    bsdf = si.bsdf(ray)
    smooth = mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
    chain = state.delta_albedo
    if chain is not None:
        here = chain.pending & active & si.is_valid() & smooth
        chain.albedo = dr.select(here, beta * bsdf.eval_diffuse_reflectance(si, here), chain.albedo)
        chain.pending = chain.pending & active & si.is_valid() & ~smooth
    active_em = active_next & smooth
    if motion is None:
        ds, em_weight = scene.sample_emitter_direction(si, sampler.next_2d(), True, active_em)
    else:
        ds, em_weight = motion.sample_emitter_direction(scene, si, sampler.next_2d(), active_em, poses)
    active_em &= ds.pdf != 0.0
    wo = si.to_local(ds.d)
    val, pdf, bs, weight = bsdf.eval_pdf_sample(ctx, si, wo, sampler.next_1d(), sampler.next_2d(), active_next)
    mis_em = dr.select(ds.delta, 1.0, mis_weight(dr, ds.pdf, pdf))
    state.radiance = dr.select(active_em, radiance + beta * val * em_weight * mis_em, radiance)

    state.ray = si.spawn_ray(si.to_world(bs.wo))
    state.beta = beta * weight
    state.eta = state.eta * bs.eta
    state.prev = _PreviousVertex(p=si.p, n=si.n, pdf=bs.pdf, delta=mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta))
    state.depth = dr.select(si.is_valid(), state.depth + 1, state.depth)
    state.roulette(opts.rr_depth, active_next)
    return (state,)


def trace(mi, scene, sampler, camera: DrCamera, opts: KernelOptions, pixel_x, pixel_y):
    """Trace one sample per lane (lane → pixel ``(pixel_x, pixel_y)``); returns a dict of Dr.Jit arrays.

    The first vertex is traced here (features, lobe split, next-event estimation, the first bounce
    and its roulette); later vertices run in a ``dr.while_loop`` over :class:`_PathState`, one
    :func:`_bounce` per iteration.

    Notes
    -----
    Random numbers are drawn in a fixed order: sub-pixel offset (2), then time (1, only with time
    sampling), lens (2, only with a thin lens), then, when paths bounce, the first vertex's light
    sample (2), BSDF sample (1 + 2) and roulette (1), then :func:`_bounce`'s per vertex. Every
    vertex draws them on every live lane, whatever it hits and whichever buffers are asked for, so
    the image bytes do not depend on ``second_hit`` or on the features.
    """
    import drjit as dr

    out = {}
    motion = None
    if isinstance(scene, ShutterMotionScene):  # shapes that move within the shutter
        scene, motion = scene.base, scene.moving

    # ------------------------------------------------------------ camera ray
    film, time, ray, pose = camera_ray(mi, sampler, camera, opts, pixel_x, pixel_y, out)
    # Every ray of this sample shares its time: the moving shapes' poses once.
    poses = None if motion is None else motion.at(ray.time)

    # ---------------------------------------------------------- first vertex
    if motion is None:
        si = scene.ray_intersect(ray, mi.RayFlags.All, True)
    else:
        si, hit_object, hit_local = motion.ray_intersect(scene, ray, True, True, poses)
    for _ in range(opts.null_skips):
        # Cut-outs: pass straight through points whose BSDF is fully transparent (mask opacity 0), so
        # that the first vertex, its features and its motion are what the camera sees. Unbiased: there
        # the BSDF is a null lobe of weight 1 and evaluates to 0 for light sampling.
        clear = si.is_valid() & (dr.min(si.bsdf(ray).eval_null_transmission(si, si.is_valid())) >= 1.0)
        ray = mi.Ray3f(dr.select(clear, si.spawn_ray(ray.d).o, ray.o), ray.d, ray.maxt, ray.time, ray.wavelengths)
        if motion is None:
            si = dr.select(clear, scene.ray_intersect(ray, mi.RayFlags.All, True, clear), si)
        else:
            si_next, object_next, local_next = motion.ray_intersect(scene, ray, True, clear, poses)
            si = dr.select(clear, si_next, si)
            hit_object = dr.select(clear, object_next, hit_object)
            hit_local = dr.select(clear, local_next, hit_local)
    valid = si.is_valid()
    emitted = si.emitter(scene).eval(si)  # environment on a miss; MIS weight 1 at the camera vertex
    diffuse = mi.Color3f(emitted)
    specular = mi.Color3f(0.0)

    if opts.features:
        # Hits use the point (w = 1), misses the ray direction (w = 0: a point at infinity).
        p = dr.select(valid, si.p, mi.Point3f(0.0))
        out["position"] = p
        out["normal"] = dr.select(valid, si.sh_frame.n, mi.Normal3f(0.0))
        out["depth"] = dr.select(
            valid, dr.dot(si.p - pose[3], camera.forward(pose)) / dr.norm(camera.forward(pose)), 0.0
        )
        if opts.motion:
            prev = camera.previous_pose(time)
            target = dr.select(valid, si.p, ray.d)
            w = dr.select(valid, 1.0, 0.0)
            now_xy, front_now = camera.project(pose, target, w)
            if opts.object_motion:
                was = dr.dispatch(si.shape, previous_point, si, valid)
                prev_xy, front_prev = camera.project(prev, dr.select(valid, was, ray.d), w)
            else:
                prev_xy, front_prev = camera.project(prev, target, w)
            keep = front_now & front_prev
            out["motion"] = dr.select(keep, mi.Vector2f(prev_xy - now_xy), mi.Vector2f(0.0))
            if motion is not None:
                on_moving = valid & (hit_object != NO_OBJECT)
                moved, front = motion.centre_motion(camera, hit_object, hit_local, on_moving)
                out["motion"] = dr.select(
                    on_moving, dr.select(front, mi.Vector2f(moved), mi.Vector2f(0.0)), out["motion"]
                )

    need_bsdf = opts.bounces or opts.features
    if not need_bsdf:
        out.update(color=diffuse, diffuse=diffuse, specular=specular)
        return out

    bsdf = si.bsdf(ray)
    ctx = mi.BSDFContext()
    ctx_diffuse = mi.BSDFContext()
    ctx_diffuse.type_mask = int(mi.BSDFFlags.Diffuse)
    active_next = valid & opts.bounces
    smooth = mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
    active_em = active_next & smooth
    if opts.bounces:
        light_uv = sampler.next_2d()
        if motion is None:
            ds, em_weight = scene.sample_emitter_direction(si, light_uv, True, active_em)
        else:
            ds, em_weight = motion.sample_emitter_direction(scene, si, light_uv, active_em, poses)
        active_em &= ds.pdf != 0.0
        wo = si.to_local(ds.d)
        sample1 = sampler.next_1d()
        sample2 = sampler.next_2d()
    else:
        wo = mi.Vector3f(0.0, 0.0, 1.0)
        sample1 = mi.Float(0.5)
        sample2 = mi.Point2f(0.5)
    split = opts.lobe_split and opts.bounces
    val, pdf, bs, weight, val_diffuse, albedo, rough = dr.dispatch(
        bsdf,
        functools.partial(first_vertex_bsdf, split, opts.features),
        ctx,
        ctx_diffuse,
        si,
        wo,
        sample1,
        sample2,
        active_em,
        valid,
    )
    if opts.features:
        out["roughness"] = dr.select(valid, rough, 0.0)
        albedo = dr.select(valid & smooth, albedo, 0.0)
        albedo_pending = valid & ~smooth

    if opts.bounces:
        mis_em = dr.select(ds.delta, 1.0, mis_weight(dr, ds.pdf, pdf))
        nee = dr.select(active_em, val * em_weight * mis_em, 0.0)
        if split:
            nee_diffuse = dr.select(active_em, val_diffuse * em_weight * mis_em, 0.0)
            diffuse += nee_diffuse
            specular += nee - nee_diffuse
        else:
            diffuse += nee

        first_is_diffuse = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Diffuse) if opts.lobe_split else mi.Bool(True)
        beta = mi.Spectrum(weight)
        eta = mi.Float(bs.eta)
        ray = si.spawn_ray(si.to_world(bs.wo))
        if opts.second_hit:
            # RPF's random parameters and second-hit features (same random numbers as without them)
            out["light"] = light_uv
            out["bounce"] = sample2
            if motion is None:
                si2 = scene.ray_intersect(ray, mi.RayFlags.All, True, active_next)
            else:
                si2 = motion.ray_intersect(scene, ray, True, active_next, poses)[0]
            hit2 = active_next & si2.is_valid()
            out["position2"] = dr.select(hit2, si2.p, mi.Point3f(0.0))
            out["normal2"] = dr.select(hit2, si2.sh_frame.n, mi.Normal3f(0.0))
        state = _PathState(
            sampler=sampler,
            ray=ray,
            beta=beta,
            eta=eta,
            depth=dr.select(valid, mi.UInt32(1), mi.UInt32(0)),
            radiance=mi.Color3f(0.0),
            prev=_PreviousVertex.of(mi, si, bs),
            active=active_next,
        )
        state.roulette(opts.rr_depth, active_next)
        if opts.features and opts.follow_delta_albedo:
            state.delta_albedo = _DeltaAlbedo(albedo=albedo, pending=albedo_pending)
        (state,) = dr.while_loop(
            state=(state,),
            cond=lambda state: state.active,
            body=functools.partial(_bounce, mi, scene, motion, poses, ctx, opts),
            label="denoisebench feature path tracer",
            max_iterations=max(opts.max_depth - 1, 1) if opts.bounded else None,
        )
        if state.delta_albedo is not None:
            albedo = state.delta_albedo.albedo
        if opts.lobe_split:
            diffuse += dr.select(first_is_diffuse, state.radiance, 0.0)
            specular += dr.select(first_is_diffuse, 0.0, state.radiance)
        else:
            diffuse += state.radiance

    if opts.features:
        out["albedo"] = albedo
    out["diffuse"] = diffuse
    out["specular"] = specular
    out["color"] = diffuse + specular
    return out
