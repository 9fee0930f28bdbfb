"""The feature path tracer for scenes with participating media: Mitsuba's ``volpath`` estimator with features.

:func:`trace` is what :func:`~denoisebench.generator.render.moments.render_moments` calls instead
of the surface tracer when ``KernelOptions.media`` is set; the render plan sets it only for a scene that
has a medium (a shape's ``interior``/``exterior``, or the sensor's), so a scene without media never
traces this code (its frames are the bytes they were before media existed).

Estimator (unbiased, as Mitsuba's ``volpath``; media and phase functions are Mitsuba's own plugins,
evaluated through ``Medium.sample_interaction`` and ``PhaseFunction.sample``/``eval_pdf``):

* **Free flight: delta tracking against the medium's majorant** (``combined_extinction``). Each event
  picks one colour channel uniformly and samples a tentative collision with that channel's majorant;
  the throughput is weighted by the transmittance over the *mixture* density of the three channels
  (one-sample MIS over channels, the balance heuristic: volpathmis's "spectral MIS"), so chromatic
  extinction costs no bias and little variance. A tentative collision is real with probability
  ``mean(sigma_t) / mean(majorant)`` (weight ``sigma_s / p``) and null otherwise (weight
  ``sigma_n / (1 - p)``; homogeneous media have ``sigma_n = 0``, every collision is real).
* **Next-event estimation through media** at every real event (medium scattering and smooth
  surfaces): one emitter sample, its transmittance estimated along the shadow ray through null
  surfaces (``eval_null_transmission``) and medium transitions: analytically in homogeneous media
  (``exp(-sigma_t d)``), by ratio tracking in heterogeneous ones; multiple importance sampling with
  the power heuristic against phase/BSDF sampling, as Mitsuba's ``path`` and ``volpath``.
* **Boundaries**: a surface whose sampled lobe is null (``null`` BSDF, a mask's transparent part) is
  crossed without counting as a vertex; any crossing of a shape with ``interior``/``exterior`` media
  switches the ray's medium (``SurfaceInteraction.target_medium``), dielectric boundaries included
  (subsurface scattering). The camera ray starts in the sensor's medium (Mitsuba XML scenes); a scene
  without a sensor (a translated USD stage) finds the medium around the camera by walking the camera
  ray to the first medium boundary it meets and taking that boundary's medium on the camera's side.
* ``max_depth`` counts real events (medium scatterings and non-null surface vertices) as Mitsuba's
  ``volpath`` does; Russian roulette after each real event from ``rr_depth`` on, with Mitsuba's
  survival probability ``min(max(throughput) * eta^2, 0.95)``.

Features of a path whose first real event is a scattering in a medium (documented in docs/architecture.md,
"Buffers"; OIDN asks for the albedo of the first *visible* event and for volumes its single-scattering
albedo):

* ``albedo``: the medium's single-scattering albedo ``sigma_s / sigma_t`` at the scattering point;
* ``normal``: 0 (a phase function has no normal; OIDN's convention for volumes is a zero normal);
* ``position``/``depth``: the scattering point; ``roughness``: 1 (scattering spreads light over all
  directions); ``motion``: the scattering point reprojected (media are static; a first hit on a moving
  mesh reprojects where its point was, as the surface tracer does);
* lobe split: light a medium scattering sends on goes to **diffuse**; a surface first vertex splits as
  in the surface tracer (next-event estimation by BSDF lobe, the rest by the sampled lobe).

Per-sample random parameters: ``medium`` is the number that drew the path's first free flight in a
medium before its first real event (0 where there is none), ``light`` is the first real event's
emitter sample, ``bounce`` its direction sample (BSDF or phase function), ``position2``/``normal2``
the second real event's point and normal (0 for a medium event, or where the path ends first).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

from denoisebench.generator.render.camera import DrCamera
from denoisebench.generator.render.media import camera_medium
from denoisebench.generator.render.motion import ShutterMotionScene
from denoisebench.generator.render.tracing import (
    KernelOptions,
    camera_ray,
    first_vertex_bsdf,
    mis_weight,
    previous_point,
)


def _channels(c) -> list:
    return [c[0], c[1], c[2]]


def _flight_weight(mi, dr, majorant, t, collided):
    """Per-channel ``transmittance / pdf`` of a free flight of length ``t`` (Color3f).

    The flight was sampled from one channel chosen uniformly, so its density is the mixture
    ``mean_c(m_c exp(-m_c t))`` for a collision at ``t`` and ``mean_c(exp(-m_c t))`` for passing a
    segment of length ``t``. Written as ``1 / mean_c(a_c exp((m_k - m_c) t))`` per channel ``k`` so
    that a grey majorant gives exactly ``1 / m`` (collision) or 1 (pass), and no 0/0 arises at large
    or infinite ``t``.
    """
    m = _channels(majorant)
    out = []
    for k in range(3):
        total = mi.Float(0.0)
        for c in range(3):
            d = m[k] - m[c]
            exponent = dr.select(d == 0.0, 0.0, d * t)
            term = dr.exp(exponent)
            total += dr.select(collided, m[c] * term, term)
        w = dr.select(total > 0.0, 3.0 / total, 0.0)
        out.append(dr.select(dr.isfinite(w), w, 0.0))
    return mi.Color3f(out[0], out[1], out[2])


def _channel_sample(mi, dr, u):
    """One uniform number → (channel 0..2, a fresh uniform number for the distance)."""
    scaled = u * 3.0
    channel = mi.UInt32(dr.minimum(scaled, 2.0))
    return channel, dr.clip(scaled - mi.Float(channel), 0.0, 0.99999994)


def _segment_ray(mi, o, d, maxt, time, wavelengths):
    return mi.Ray3f(o, d, maxt, time, wavelengths)


@dataclass
class _Shadow:
    """State of the shadow-ray transmittance loop (a Dr.Jit PyTree)."""

    sampler: object
    o: object
    remaining: object
    medium: object
    tr: object
    active: object
    si: object  # the surface ahead, kept across null collisions (``fresh``: intersect anew)
    fresh: object


def _transmittance(mi, dr, scene, sampler, o, d, dist, medium, time, wavelengths, active):
    """Transmittance from ``o`` along ``d`` over ``dist`` through null surfaces and media: (Color3f, sampler).

    Homogeneous media contribute ``exp(-sigma_t * length)`` exactly; heterogeneous ones by ratio
    tracking (each tentative collision multiplies by ``sigma_n`` times the flight weight). Any
    surface that is not fully or partly null (``eval_null_transmission``) blocks the ray.
    """
    state = _Shadow(
        sampler=sampler,
        o=mi.Point3f(o),
        remaining=mi.Float(dist),
        medium=mi.MediumPtr(medium),
        tr=mi.Color3f(1.0),
        active=mi.Bool(active),
        si=dr.zeros(mi.SurfaceInteraction3f, dr.width(dist)),
        fresh=mi.Bool(True),
    )

    def cond(state):
        return state.active

    def body(state):
        active = state.active & (state.remaining > 0.0)
        ray = _segment_ray(mi, state.o, d, state.remaining, time, wavelengths)
        fresh = active & state.fresh
        si = dr.select(fresh, scene.ray_intersect(ray, mi.RayFlags.All, False, fresh), state.si)
        end = dr.minimum(si.t, state.remaining)
        medium = state.medium
        in_medium = active & (medium != None)  # noqa: E711 (a Dr.Jit pointer comparison)
        channel, u = _channel_sample(mi, dr, state.sampler.next_1d())
        mray = _segment_ray(mi, state.o, d, end, time, wavelengths)
        mei = medium.sample_interaction(mray, u, channel, in_medium)
        homogeneous = in_medium & medium.is_homogeneous()
        collided = in_medium & ~homogeneous & mei.is_valid()
        majorant = mei.combined_extinction
        tr = state.tr
        # homogeneous: the exact transmittance of the segment inside the medium
        length = dr.maximum(end - mei.mint, 0.0)
        exact = dr.exp(-majorant * length)
        tr = dr.select(homogeneous, tr * dr.select(dr.isfinite(length), exact, dr.select(majorant > 0, 0.0, 1.0)), tr)
        # heterogeneous: ratio tracking
        flown = dr.select(collided, mei.t, end) - mei.mint
        passing = in_medium & ~homogeneous & ~collided
        flight = _flight_weight(mi, dr, majorant, flown, collided)
        tr = dr.select(collided, tr * flight * mei.sigma_n, tr)
        tr = dr.select(passing, tr * flight, tr)
        # a surface before the end: its null transmission, and the medium behind it
        at_surface = active & ~collided & si.is_valid() & (si.t < state.remaining)
        bsdf = si.bsdf(ray)
        tr = dr.select(at_surface, tr * bsdf.eval_null_transmission(si, at_surface), tr)
        next_medium = dr.select(at_surface & si.is_medium_transition(), si.target_medium(d), medium)
        moved = dr.select(collided, mei.t, si.t)
        o = dr.select(collided, mei.p, dr.select(at_surface, si.spawn_ray(d).o, state.o))
        state.o = mi.Point3f(o)
        state.remaining = dr.select(collided | at_surface, state.remaining - moved, state.remaining)
        state.medium = next_medium
        state.tr = tr
        state.si = si
        state.si.t = dr.select(collided, si.t - mei.t, si.t)
        state.fresh = ~collided
        state.active = (collided | at_surface) & (dr.max(tr) > 0.0) & (state.remaining > 0.0)
        return (state,)

    (state,) = dr.while_loop(state=(state,), cond=cond, body=body, label="denoisebench volpath shadow")
    return state.tr, state.sampler


#: Surfaces a probe passes (those that bound no medium) before it gives up: the camera is then in none.
PROBE_SURFACES = 16


def _enclosing_medium(mi, dr, scene, ray):
    """The medium around each camera ray's origin (MediumPtr per lane): walk along the ray past surfaces
    that bound no medium to the first that does; its medium on the origin's side encloses the origin
    (none when the walk escapes). Closed boundaries make this exact; :data:`PROBE_SURFACES` bounds it."""
    found = dr.zeros(mi.MediumPtr, dr.width(ray.o.x))
    origin = mi.Point3f(ray.o)
    active = dr.full(mi.Bool, True, dr.width(ray.o.x))
    count = mi.UInt32(0)

    def body(origin, found, active, count):
        si = scene.ray_intersect(mi.Ray3f(origin, ray.d, dr.inf, ray.time, ray.wavelengths), active)
        boundary = active & si.is_valid() & si.is_medium_transition()
        found = dr.select(boundary, si.target_medium(-ray.d), found)
        origin = dr.select(active & si.is_valid(), si.spawn_ray(ray.d).o, origin)
        active = active & si.is_valid() & ~boundary & (count + 1 < PROBE_SURFACES)
        return origin, found, active, count + 1

    _, found, _, _ = dr.while_loop(
        state=(origin, found, active, count),
        cond=lambda origin, found, active, count: active,
        body=body,
        label="denoisebench camera medium probe",
    )
    return found


@dataclass
class _VolState:
    """The volumetric path loop's state (a Dr.Jit PyTree); fields as in :func:`trace`."""

    sampler: object
    ray: object
    medium: object
    beta: object
    eta: object
    depth: object
    radiance: object  # everything gathered
    specular: object  # its specular share
    route_specular: object  # later light goes to specular (the first real event sampled a non-diffuse lobe)
    prev_p: object
    prev_n: object
    prev_pdf: object
    prev_delta: object
    active: object
    si: object  # the surface ``ray`` meets, kept across null collisions (``fresh``: intersect anew)
    fresh: object
    feats: dict | None = None


def trace(mi, scene, sampler, camera: DrCamera, opts: KernelOptions, pixel_x, pixel_y):
    """Trace one sample per lane through a scene with media; the same outputs as the surface tracer's ``trace``.

    Notes
    -----
    Random numbers: sub-pixel offset (2), time (1, motion blur), lens (2, thin lens), then per loop
    iteration on every live lane: channel and distance (1), real-or-null (1), emitter sample (2),
    the shadow loop's (1 per segment), direction sample (1 + 2), roulette (1).
    """
    import drjit as dr

    if isinstance(scene, ShutterMotionScene):
        raise NotImplementedError("participating media with shapes that move within the shutter are not supported")
    out = {}
    film, time, ray, pose = camera_ray(mi, sampler, camera, opts, pixel_x, pixel_y, out)
    camera_dir = mi.Vector3f(ray.d)

    lanes = dr.width(film.x)
    start_medium = camera_medium(scene)
    medium = dr.zeros(mi.MediumPtr, lanes)
    if start_medium is not None:
        medium = dr.select(dr.full(mi.Bool, True, lanes), mi.MediumPtr(start_medium), medium)
    elif not scene.sensors():
        # A scene without a sensor (a translated USD stage: our camera is no Mitsuba sensor): the camera
        # is in the medium whose boundary it sees from inside (a camera in a fog box).
        medium = _enclosing_medium(mi, dr, scene, ray)

    features = opts.features
    feats = None
    if features:
        feats = {
            "p": mi.Point3f(0.0),
            "n": mi.Normal3f(0.0),
            "albedo": mi.Color3f(0.0),
            "rough": mi.Float(0.0),
            "hit": mi.Bool(False),
            "pending": mi.Bool(False),  # albedo still to be read past a delta chain
            "medium_u": mi.Float(0.0),  # the number of the first free flight in a medium (0: none)
            "medium_set": mi.Bool(False),
        }
        if opts.object_motion:
            feats["was"] = mi.Point3f(0.0)  # where the first event's surface point was one frame earlier
        if opts.second_hit:
            feats.update(light=mi.Point2f(0.0), bounce=mi.Point2f(0.0), p2=mi.Point3f(0.0), n2=mi.Normal3f(0.0))
    state = _VolState(
        sampler=sampler,
        ray=ray,
        medium=medium,
        beta=mi.Color3f(1.0),
        eta=mi.Float(1.0),
        depth=dr.zeros(mi.UInt32, lanes),
        radiance=mi.Color3f(0.0),
        specular=mi.Color3f(0.0),
        route_specular=mi.Bool(False),
        prev_p=mi.Point3f(ray.o),
        prev_n=mi.Normal3f(0.0),
        prev_pdf=mi.Float(1.0),
        prev_delta=mi.Bool(True),  # the camera: an emitter it sees has MIS weight 1
        active=dr.full(mi.Bool, True, lanes),
        si=dr.zeros(mi.SurfaceInteraction3f, lanes),
        fresh=dr.full(mi.Bool, True, lanes),
        feats=feats,
    )
    body = functools.partial(_iteration, mi, dr, scene, opts)
    (state,) = dr.while_loop(
        state=(state,), cond=lambda state: state.active, body=body, label="denoisebench volumetric path tracer"
    )

    specular = state.specular if opts.lobe_split else mi.Color3f(0.0)
    out["color"] = state.radiance
    out["specular"] = specular
    out["diffuse"] = state.radiance - specular
    if features:
        f = state.feats
        hit = f["hit"]
        out["position"] = dr.select(hit, f["p"], mi.Point3f(0.0))
        out["normal"] = dr.select(hit, f["n"], mi.Normal3f(0.0))
        out["depth"] = dr.select(
            hit, dr.dot(f["p"] - pose[3], camera.forward(pose)) / dr.norm(camera.forward(pose)), 0.0
        )
        out["roughness"] = dr.select(hit, f["rough"], 0.0)
        out["albedo"] = dr.select(f["pending"], 0.0, f["albedo"])
        out["medium"] = f["medium_u"]
        if opts.motion:
            prev = camera.previous_pose(time)
            target = dr.select(hit, f["p"], camera_dir)
            w = dr.select(hit, 1.0, 0.0)
            now_xy, front_now = camera.project(pose, target, w)
            was = dr.select(hit, f["was"], camera_dir) if opts.object_motion else target
            prev_xy, front_prev = camera.project(prev, was, w)
            keep = front_now & front_prev
            out["motion"] = dr.select(keep, mi.Vector2f(prev_xy - now_xy), mi.Vector2f(0.0))
        if opts.second_hit:
            out["light"] = f["light"]
            out["bounce"] = f["bounce"]
            out["position2"] = f["p2"]
            out["normal2"] = f["n2"]
    return out


def _iteration(mi, dr, scene, opts: KernelOptions, state: _VolState):
    """One event of the volumetric path: a null or real medium collision, or a surface (module docstring)."""
    sampler = state.sampler
    ray, medium, beta, active = state.ray, state.medium, state.beta, state.active
    first = active & (state.depth == 0)

    # After a null collision the ray goes on along the same line: the surface ahead is the one found
    # before, nearer by the distance flown (no new traversal; Mitsuba's volpath does the same).
    fresh = active & state.fresh
    si = dr.select(fresh, scene.ray_intersect(ray, mi.RayFlags.All, False, fresh), state.si)
    end = dr.minimum(si.t, ray.maxt)

    # ---------------------------------------------------------------- medium
    in_medium = active & (medium != None)  # noqa: E711 (a Dr.Jit pointer comparison)
    flight_u = sampler.next_1d()
    channel, u = _channel_sample(mi, dr, flight_u)
    mray = mi.Ray3f(ray.o, ray.d, end, ray.time, ray.wavelengths)
    mei = medium.sample_interaction(mray, u, channel, in_medium)
    collided = in_medium & mei.is_valid()
    majorant = mei.combined_extinction
    flown = dr.select(collided, mei.t, end) - mei.mint
    beta = dr.select(in_medium, beta * _flight_weight(mi, dr, majorant, flown, collided), beta)
    beta_arrive = beta  # what reaches this event (the delta-chain albedo reads it)
    p_real = dr.clip(dr.mean(mei.sigma_t) / dr.maximum(dr.mean(majorant), 1e-30), 0.0, 1.0)
    real = collided & (sampler.next_1d() < p_real)
    null = collided & ~real
    beta = dr.select(real, beta * mei.sigma_s / dr.maximum(p_real, 1e-30), beta)
    beta = dr.select(null, beta * mei.sigma_n / dr.maximum(1.0 - p_real, 1e-30), beta)

    # ---------------------------------------------------------------- surface (or escape)
    at_surface = active & ~collided
    prev_it = mi.Interaction3f(dr.zeros(mi.Float), ray.time, ray.wavelengths, state.prev_p, state.prev_n)
    ds_hit = mi.DirectionSample3f(scene, si, prev_it)
    em_pdf = scene.pdf_emitter_direction(prev_it, ds_hit, at_surface & ~state.prev_delta)
    mis_hit = mis_weight(dr, state.prev_pdf, em_pdf)
    emitted = ds_hit.emitter.eval(si, at_surface & (state.prev_pdf > 0.0))
    gathered = dr.select(at_surface, beta * mis_hit * emitted, 0.0)
    radiance = state.radiance + gathered
    specular = state.specular + dr.select(state.route_specular, gathered, 0.0)
    on_surface = at_surface & si.is_valid()

    # ---------------------------------------------------------------- vertex: light and direction
    vertex = real | on_surface
    can_go = vertex
    if opts.bounded:
        can_go &= state.depth + 1 < opts.max_depth
    it = mi.Interaction3f(
        dr.select(real, mei.t, si.t),
        ray.time,
        ray.wavelengths,
        dr.select(real, mei.p, si.p),
        dr.select(real, mi.Normal3f(0.0), si.n),
    )
    bsdf = si.bsdf(ray)
    smooth = mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
    want_light = can_go & (real | smooth)
    light_uv = sampler.next_2d()
    ds, em_weight = scene.sample_emitter_direction(it, light_uv, False, want_light)
    want_light &= ds.pdf != 0.0
    shadow = it.spawn_ray(ds.d)
    dist = dr.select(dr.isfinite(ds.dist), dr.norm(ds.p - shadow.o) * (1.0 - mi.math.ShadowEpsilon), dr.inf)
    start_medium = dr.select(on_surface & si.is_medium_transition(), si.target_medium(ds.d), medium)
    tr, sampler = _transmittance(
        mi, dr, scene, sampler, shadow.o, ds.d, dist, start_medium, ray.time, ray.wavelengths, want_light
    )
    sample1 = sampler.next_1d()
    sample2 = sampler.next_2d()

    # phase function (medium events)
    phase_ctx = mi.PhaseFunctionContext(None)
    phase = mei.medium.phase_function()
    phase_val, phase_pdf = phase.eval_pdf(phase_ctx, mei, ds.d, want_light & real)
    phase_wo, phase_weight, phase_dir_pdf = phase.sample(phase_ctx, mei, sample1, sample2, can_go & real)

    # BSDF (surface events), features of a first surface vertex
    ctx = mi.BSDFContext()
    ctx_diffuse = mi.BSDFContext()
    ctx_diffuse.type_mask = int(mi.BSDFFlags.Diffuse)
    split = opts.lobe_split
    wo_local = si.to_local(ds.d)
    val, pdf, bs, weight, val_diffuse, albedo, rough = dr.dispatch(
        bsdf,
        functools.partial(first_vertex_bsdf, split, opts.features),
        ctx,
        ctx_diffuse,
        si,
        wo_local,
        sample1,
        sample2,
        want_light & on_surface & first,
        on_surface,
    )

    nee_f = dr.select(real, phase_val, val)
    nee_pdf = dr.select(real, phase_pdf, pdf)
    mis_em = dr.select(ds.delta, 1.0, mis_weight(dr, ds.pdf, nee_pdf))
    nee = dr.select(want_light, beta * nee_f * em_weight * tr * mis_em, 0.0)
    radiance += nee
    if split:
        nee_diffuse = dr.select(want_light & on_surface & first, beta * val_diffuse * em_weight * tr * mis_em, 0.0)
        first_surface_nee = dr.select(on_surface & first, nee - nee_diffuse, 0.0)
        specular += dr.select(first, first_surface_nee, dr.select(state.route_specular, nee, 0.0))

    # ---------------------------------------------------------------- the next ray
    null_surface = on_surface & mi.has_flag(bs.sampled_type, mi.BSDFFlags.Null)
    surface_vertex = on_surface & ~null_surface
    vertex = real | surface_vertex
    go_surface = on_surface & (null_surface | can_go) & (bs.pdf > 0.0)
    go_medium = can_go & real & (phase_dir_pdf > 0.0)
    surface_dir = si.to_world(bs.wo)
    new_ray_surface = si.spawn_ray(surface_dir)
    new_ray_medium = mei.spawn_ray(phase_wo)
    new_ray_null = mi.Ray3f(mei.p, ray.d, ray.maxt - mei.t, ray.time, ray.wavelengths)
    next_ray = dr.select(go_medium, new_ray_medium, dr.select(null, new_ray_null, new_ray_surface))
    beta = dr.select(go_medium, beta * phase_weight, dr.select(go_surface, beta * weight, beta))
    eta = dr.select(go_surface, state.eta * bs.eta, state.eta)
    next_medium = dr.select(go_surface & si.is_medium_transition(), si.target_medium(surface_dir), medium)

    if state.feats is not None:
        f = state.feats
        here = first & vertex
        albedo_medium = dr.select(dr.mean(mei.sigma_t) > 0.0, mei.sigma_s / dr.maximum(mei.sigma_t, 1e-30), 0.0)
        albedo_here = dr.select(real, albedo_medium, dr.select(smooth, albedo, 0.0))
        f["p"] = dr.select(here, dr.select(real, mei.p, si.p), f["p"])
        f["n"] = dr.select(here & surface_vertex, si.sh_frame.n, dr.select(here, mi.Normal3f(0.0), f["n"]))
        f["rough"] = dr.select(here, dr.select(real, 1.0, rough), f["rough"])
        f["hit"] = f["hit"] | here
        if opts.object_motion:  # moving meshes: the hit point's previous-frame position (media are static)
            at_mesh = here & surface_vertex
            was = dr.dispatch(si.shape, previous_point, si, at_mesh)
            f["was"] = dr.select(at_mesh, was, dr.select(here, mei.p, f["was"]))
        f["albedo"] = dr.select(here, albedo_here, f["albedo"])
        flight = first & in_medium & ~f["medium_set"]
        f["medium_u"] = dr.select(flight, flight_u, f["medium_u"])
        f["medium_set"] = f["medium_set"] | flight
        if opts.follow_delta_albedo:
            # the albedo looks through delta surfaces (mirror, glass) to the first smooth vertex or scattering
            resolve = f["pending"] & (real | (surface_vertex & smooth))
            f["albedo"] = dr.select(resolve, beta_arrive * albedo_here, f["albedo"])
            f["pending"] = (f["pending"] & ~resolve) | (here & surface_vertex & ~smooth)
        if opts.second_hit:
            f["light"] = dr.select(here, light_uv, f["light"])
            f["bounce"] = dr.select(here, sample2, f["bounce"])
            second = vertex & (state.depth == 1)
            f["p2"] = dr.select(second, dr.select(real, mei.p, si.p), f["p2"])
            f["n2"] = dr.select(second & surface_vertex, si.sh_frame.n, dr.select(second, mi.Normal3f(0.0), f["n2"]))
        state.feats = f

    if split:
        first_diffuse = dr.select(real, mi.Bool(True), mi.has_flag(bs.sampled_type, mi.BSDFFlags.Diffuse))
        state.route_specular = dr.select(first & vertex, ~first_diffuse, state.route_specular)

    # previous real vertex (MIS at the next emitter hit)
    state.prev_p = dr.select(vertex, dr.select(real, mei.p, si.p), state.prev_p)
    state.prev_n = dr.select(vertex, dr.select(real, mi.Normal3f(0.0), si.n), state.prev_n)
    state.prev_pdf = dr.select(go_medium, phase_dir_pdf, dr.select(surface_vertex, bs.pdf, state.prev_pdf))
    state.prev_delta = dr.select(
        vertex, surface_vertex & mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta), state.prev_delta
    )

    depth = dr.select(vertex, state.depth + 1, state.depth)
    keep = null | go_medium | go_surface
    # Russian roulette after a real event
    beta_max = dr.max(beta)
    rr_prob = dr.minimum(beta_max * dr.square(eta), 0.95)
    rr_active = vertex & (depth >= opts.rr_depth)
    rr_continue = sampler.next_1d() < rr_prob
    beta = dr.select(rr_active, beta * dr.rcp(rr_prob), beta)
    keep &= ~rr_active | rr_continue
    keep &= dr.max(beta) != 0.0

    state.sampler = sampler
    state.ray = next_ray
    state.si = si
    state.si.t = dr.select(null, si.t - mei.t, si.t)
    state.fresh = ~null
    state.medium = next_medium
    state.beta = beta
    state.eta = eta
    state.depth = depth
    state.radiance = radiance
    state.specular = specular
    state.active = active & keep
    return (state,)
