"""The feature path tracer: one Dr.Jit kernel yields color, the lobe split and every feature per sample.

The estimator is Mitsuba 3's ``path`` integrator (``src/integrators/path.cpp``) written in Python:
next-event estimation at every non-delta vertex, BSDF sampling to continue, both combined by multiple
importance sampling with the power heuristic; Russian roulette from ``rr_depth`` with Mitsuba's
survival probability ``min(max(throughput) * eta^2, 0.95)``; ``max_depth`` in Mitsuba's convention
(1: only emitters seen directly, 2: direct lighting, ...). It is therefore an unbiased estimator of
the very image ``path`` renders at the same ``max_depth`` (tests/test_feature_renderer.py checks
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
* ``motion``: the first-hit point projected through the pinhole (lens center) of the camera one frame
  earlier than the ray's time, minus its projection at the ray's time (pixels, x right, y down).

Background (miss) convention: color is the environment's radiance (0 without one); albedo, normal,
depth, position and roughness are 0; motion reprojects the ray *direction* (a point at infinity, so
rotation only). Points behind either camera get zero motion. At frame 0 there is no previous
frame and motion is 0. Everything is finite.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

from denoisebench.generator.render_camera import DrCamera


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


def _mis_weight(dr, pdf_a, pdf_b):
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


def _first_vertex_bsdf(split, want_features, bsdf, ctx, ctx_diffuse, si, wo, sample1, sample2, active_em, active):
    """Everything the first vertex asks of its BSDF, in one dynamic dispatch per BSDF instance."""
    import drjit as dr
    import mitsuba as mi

    val, pdf, bs, weight = bsdf.eval_pdf_sample(ctx, si, wo, sample1, sample2, active)
    val_diffuse = bsdf.eval(ctx_diffuse, si, wo, active_em) if split else mi.Color3f(0.0)
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


def trace(mi, scene, sampler, camera: DrCamera, opts: KernelOptions, pixel_x, pixel_y):
    """Trace one sample per lane (lane → pixel ``(pixel_x, pixel_y)``); returns a dict of Dr.Jit arrays.

    Random numbers are drawn in a fixed order: sub-pixel offset (2), then time (1, only with time
    sampling), lens (2, only with a thin lens), then the path's own.
    """
    import drjit as dr

    setup = camera.setup
    out = {}

    # ------------------------------------------------------------ camera ray
    if opts.jitter:
        offset = sampler.next_2d()
    else:
        offset = mi.Point2f(0.5, 0.5)
    film = mi.Point2f(mi.Float(pixel_x) + offset.x, mi.Float(pixel_y) + offset.y)
    out["pixel"] = offset
    if setup.time_sampling:
        shutter = sampler.next_1d()
        time = camera.sample_time(shutter)
        out["time"] = shutter
    else:
        time = camera.frame_time + mi.Float(0.0) * film.x  # per-lane array
    if setup.thin_lens:
        lens_uv = sampler.next_2d()
        out["lens"] = lens_uv
    else:
        lens_uv = None
    ray, pose = camera.generate_ray(film, lens_uv, time)

    # ---------------------------------------------------------- first vertex
    si = scene.ray_intersect(ray, mi.RayFlags.All, True)
    valid = si.is_valid()
    emitted = si.emitter(scene).eval(si)  # environment on a miss; MIS weight 1 at the camera vertex
    diffuse = mi.Color3f(emitted)
    specular = mi.Color3f(0.0)

    if opts.features:
        # Hits use the point (w = 1), misses the ray direction (w = 0: a point at infinity).
        p = dr.select(valid, si.p, mi.Point3f(0.0))
        out["position"] = p
        out["normal"] = dr.select(valid, si.sh_frame.n, mi.Normal3f(0.0))
        out["depth"] = dr.select(valid, dr.dot(si.p - pose[3], camera.forward(pose)) / dr.norm(camera.forward(pose)), 0.0)
        if opts.motion:
            prev = camera.previous_pose(time)
            target = dr.select(valid, si.p, ray.d)
            w = dr.select(valid, 1.0, 0.0)
            now_xy, front_now = camera.project(pose, target, w)
            prev_xy, front_prev = camera.project(prev, target, w)
            keep = front_now & front_prev
            out["motion"] = dr.select(keep, mi.Vector2f(prev_xy - now_xy), mi.Vector2f(0.0))

    need_bsdf = opts.max_depth > 1 or opts.features
    if not need_bsdf:
        out.update(color=diffuse, diffuse=diffuse, specular=specular)
        return out

    bsdf = si.bsdf(ray)
    ctx = mi.BSDFContext()
    ctx_diffuse = mi.BSDFContext()
    ctx_diffuse.type_mask = int(mi.BSDFFlags.Diffuse)
    active_next = valid & (opts.max_depth > 1)
    smooth = mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
    active_em = active_next & smooth
    if opts.max_depth > 1:
        ds, em_weight = scene.sample_emitter_direction(si, sampler.next_2d(), True, active_em)
        active_em &= ds.pdf != 0.0
        wo = si.to_local(ds.d)
        sample1 = sampler.next_1d()
        sample2 = sampler.next_2d()
    else:
        wo = mi.Vector3f(0.0, 0.0, 1.0)
        sample1 = mi.Float(0.5)
        sample2 = mi.Point2f(0.5)
    split = opts.lobe_split and opts.max_depth > 1
    val, pdf, bs, weight, val_diffuse, albedo, rough = dr.dispatch(
        bsdf, functools.partial(_first_vertex_bsdf, split, opts.features),
        ctx, ctx_diffuse, si, wo, sample1, sample2, active_em, valid,
    )
    if opts.features:
        out["roughness"] = dr.select(valid, rough, 0.0)
        albedo = dr.select(valid & smooth, albedo, 0.0)
        albedo_pending = valid & ~smooth

    if opts.max_depth > 1:
        mis_em = dr.select(ds.delta, 1.0, _mis_weight(dr, ds.pdf, pdf))
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
        prev_p = mi.Point3f(si.p)
        prev_n = mi.Normal3f(si.n)
        prev_pdf = mi.Float(bs.pdf)
        prev_delta = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
        depth = dr.select(valid, mi.UInt32(1), mi.UInt32(0))
        beta_max = dr.max(beta)
        rr_prob = dr.minimum(beta_max * dr.square(eta), 0.95)
        rr_active = depth >= opts.rr_depth
        rr_continue = sampler.next_1d() < rr_prob
        beta = dr.select(rr_active, beta * dr.rcp(rr_prob), beta)
        active = active_next & (~rr_active | rr_continue) & (beta_max != 0.0)
        rest = mi.Color3f(0.0)
        if not (opts.features and opts.follow_delta_albedo):
            albedo_pending = mi.Bool(False)
        follow = opts.features and opts.follow_delta_albedo

        def cond(sampler, ray, beta, eta, depth, rest, prev_p, prev_n, prev_pdf, prev_delta, active, albedo, pending):
            return active

        def body(sampler, ray, beta, eta, depth, rest, prev_p, prev_n, prev_pdf, prev_delta, active, albedo, pending):
            si = scene.ray_intersect(ray, mi.RayFlags.All, False, active)
            prev_si = mi.Interaction3f(dr.zeros(mi.Float), ray.time, mi.Color0f(), prev_p, prev_n)
            ds = mi.DirectionSample3f(scene, si, prev_si)
            em_pdf = scene.pdf_emitter_direction(prev_si, ds, active & ~prev_delta)
            mis = _mis_weight(dr, prev_pdf, em_pdf)
            emitted = ds.emitter.eval(si, active & (prev_pdf > 0.0))
            rest = dr.select(active, rest + beta * mis * emitted, rest)

            active_next = active & (depth + 1 < opts.max_depth) & si.is_valid()
            bsdf = si.bsdf(ray)
            smooth = mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
            if follow:
                here = pending & active & si.is_valid() & smooth
                albedo = dr.select(here, beta * bsdf.eval_diffuse_reflectance(si, here), albedo)
                pending = pending & active & si.is_valid() & ~smooth
            active_em = active_next & smooth
            ds, em_weight = scene.sample_emitter_direction(si, sampler.next_2d(), True, active_em)
            active_em &= ds.pdf != 0.0
            wo = si.to_local(ds.d)
            val, pdf, bs, weight = bsdf.eval_pdf_sample(
                ctx, si, wo, sampler.next_1d(), sampler.next_2d(), active_next
            )
            mis_em = dr.select(ds.delta, 1.0, _mis_weight(dr, ds.pdf, pdf))
            rest = dr.select(active_em, rest + beta * val * em_weight * mis_em, rest)

            ray = si.spawn_ray(si.to_world(bs.wo))
            beta = beta * weight
            eta = eta * bs.eta
            prev_p = si.p
            prev_n = si.n
            prev_pdf = bs.pdf
            prev_delta = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)

            depth = dr.select(si.is_valid(), depth + 1, depth)
            beta_max = dr.max(beta)
            rr_prob = dr.minimum(beta_max * dr.square(eta), 0.95)
            rr_active = depth >= opts.rr_depth
            rr_continue = sampler.next_1d() < rr_prob
            beta = dr.select(rr_active, beta * dr.rcp(rr_prob), beta)
            active = active_next & (~rr_active | rr_continue) & (beta_max != 0.0)
            return sampler, ray, beta, eta, depth, rest, prev_p, prev_n, prev_pdf, prev_delta, active, albedo, pending

        albedo_state = albedo if opts.features else mi.Color3f(0.0)
        state = dr.while_loop(
            state=(sampler, ray, beta, eta, depth, rest, prev_p, prev_n, prev_pdf, prev_delta, active,
                   albedo_state, albedo_pending),
            cond=cond,
            body=body,
            label="denoisebench feature path tracer",
            max_iterations=max(opts.max_depth - 1, 1),
        )
        rest = state[5]
        if opts.features:
            albedo = state[11]
        if opts.lobe_split:
            diffuse += dr.select(first_is_diffuse, rest, 0.0)
            specular += dr.select(first_is_diffuse, 0.0, rest)
        else:
            diffuse += rest

    if opts.features:
        out["albedo"] = albedo
    out["diffuse"] = diffuse
    out["specular"] = specular
    out["color"] = diffuse + specular
    return out



def _channel_type(mi, channels: int):
    return {1: mi.Float, 2: mi.Vector2f, 3: mi.Color3f}[channels]


def render_moments(mi, scene, sampler, camera: DrCamera, opts: KernelOptions, pixel_x, pixel_y, count,
                   names: dict, sample_targets: dict | None = None, sample_slot=None):
    """Each lane traces ``count`` samples of pixel ``(pixel_x, pixel_y)`` in a loop, keeping running
    per-lane moments (Welford: mean and sum of squared deviations) of the buffers in ``names``
    (name → channels): one kernel yields per-pixel statistics without storing samples.

    ``sample_targets`` (name → (flat Float array, channels)) also receives per-sample values: sample
    ``s`` of a lane is written to row ``sample_slot(s)`` (row-major, channels innermost).
    Returns ``{name: (mean, m2)}`` as Dr.Jit arrays (one entry per lane).
    """
    import drjit as dr

    lanes = dr.width(pixel_x)
    mean = {k: dr.zeros(_channel_type(mi, c), lanes) for k, c in names.items()}
    m2 = {k: dr.zeros(_channel_type(mi, c), lanes) for k, c in names.items()}
    s = dr.zeros(mi.UInt32, lanes)
    count = mi.UInt32(count)

    def cond(sampler, s, mean, m2):
        return s < count

    def body(sampler, s, mean, m2):
        out = trace(mi, scene, sampler, camera, opts, pixel_x, pixel_y)
        inv_n = dr.rcp(mi.Float(s + 1))
        new_mean, new_m2 = {}, {}
        for k, c in names.items():
            value = _channel_type(mi, c)(out[k])
            delta = value - mean[k]
            new_mean[k] = dr.fma(delta, inv_n, mean[k])
            new_m2[k] = dr.fma(delta, value - new_mean[k], m2[k])
        if sample_targets:
            slot = sample_slot(s)
            for k, (target, channels) in sample_targets.items():
                value = out[k]
                for c in range(channels):
                    dr.scatter(target, value if channels == 1 else value[c], slot * channels + c)
        return sampler, s + 1, new_mean, new_m2

    sampler, s, mean, m2 = dr.while_loop(
        state=(sampler, s, mean, m2), cond=cond, body=body, label="denoisebench samples per pixel"
    )
    return {k: (mean[k], m2[k]) for k in names}


def merge_lane_moments(mi, moments: dict, lane_count, groups: int, total: int) -> dict:
    """Merge the moments of ``groups`` consecutive lanes (one pixel's) into per-pixel moments.

    ``moments`` is :func:`render_moments`' result, ``lane_count`` the samples each lane took (they
    add up to ``total`` per pixel). Chan et al.'s pairwise rule generalised to K groups:
    ``mean = Σ n_k mean_k / n`` and ``M2 = Σ (M2_k + n_k (mean_k - mean)²)``.

    Notes:
        Block reductions need a pixel's lanes to be contiguous (lane = pixel * groups + group).
        Merging on the device keeps the host transfer at one value per pixel, which matters for
        small images, where every pixel gets many lanes.
    """
    import drjit as dr

    weight = mi.Float(lane_count)
    lanes = dr.width(lane_count)
    owner = dr.arange(mi.UInt32, lanes) // dr.opaque(mi.UInt32, groups)
    inv_total = dr.opaque(mi.Float, 1.0 / total)

    def block_sums(values: dict) -> dict:
        # Scatter-adds into targets made beforehand fuse into one kernel (block_sum would allocate,
        # and so launch, once per buffer).
        sums = {k: dr.zeros(type(v), lanes // groups) for k, v in values.items()}
        dr.eval(sums)
        for k, v in values.items():
            dr.scatter_add(sums[k], v, owner)
        dr.eval(sums)
        return sums

    means = block_sums({k: mean * (weight * inv_total) for k, (mean, _) in moments.items()})
    m2s = block_sums({
        k: m2 + weight * dr.square(mean - dr.gather(type(mean), means[k], owner)) for k, (mean, m2) in moments.items()
    })
    return {k: (means[k], m2s[k]) for k in moments}
