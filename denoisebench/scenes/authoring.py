"""Authoring helpers shared by the scene families: one :class:`SceneBuilder` per stage.

The builder writes only the USD subset the translator reads (see the family modules and
``denoisebench/generator``): a ``/World`` Xform default prim; ``UsdGeom`` meshes and primitives
placed by translate/rotateXYZ/scale ops; ``UsdPreviewSurface`` materials under ``/World/Looks``
with ``UsdUVTexture`` image textures (``textures/<name>.png`` beside the stage); ``UsdLux`` lights;
one ``UsdGeom.Camera`` at ``/World/Camera`` whose single ``xformOp:transform`` is time-sampled at
every frame; and the family's metadata in the root layer's ``customLayerData``.

Determinism: the stage is built in memory and exported once; the exported layer carries no
``doc`` string, timestamp or absolute path, and every number comes from the family's seeded
``numpy.random.Generator``. Floats are rounded to a fixed number of decimals before they are
written, so last-bit differences in transcendental functions cannot change the text.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade, Vt

from denoisebench.scenes.camera_paths import look_at
from denoisebench.scenes.effects import METADATA_KEY, validate_effects
from denoisebench.scenes.geometry import MeshData
from denoisebench.scenes.textures import write_png

STAGE_FILENAME = "scene.usda"
TEXTURE_DIR = "textures"
FPS = 24.0
_DECIMALS = 6  # rounding of every authored float


def _r(x) -> float:
    v = round(float(x), _DECIMALS)
    return 0.0 if v == 0.0 else v  # no "-0"


def _vec3f(v) -> Gf.Vec3f:
    return Gf.Vec3f(*(_r(c) for c in v))


def _vec3d(v) -> Gf.Vec3d:
    return Gf.Vec3d(*(_r(c) for c in v))


def _color(v) -> Gf.Vec3f:
    if np.isscalar(v):
        v = (v, v, v)
    return _vec3f(v)


def _matrix(m: np.ndarray) -> Gf.Matrix4d:
    m = np.round(np.asarray(m, dtype=np.float64), _DECIMALS) + 0.0  # + 0.0 turns -0 into 0
    return Gf.Matrix4d(*[[float(m[i, j]) for j in range(4)] for i in range(4)])


def _sanitize(name: str) -> str:
    out = "".join(c if (c.isalnum() or c == "_") else "_" for c in name)
    return out if out and not out[0].isdigit() else "_" + out


class SceneBuilder:
    """Builds one family's stage in memory, then :meth:`save` writes ``scene.usda`` + textures."""

    def __init__(
        self,
        out_dir,
        *,
        family: str,
        seed: int,
        frames: int,
        effects,
        up_axis: str = "Y",
        meters_per_unit: float = 1.0,
    ) -> None:
        if isinstance(frames, bool) or not isinstance(frames, (int, np.integer)) or frames < 1:
            raise ValueError(f"frames must be an integer >= 1, got {frames!r}")
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
        if up_axis not in ("Y", "Z"):
            raise ValueError(f"up_axis must be 'Y' or 'Z', got {up_axis!r}")
        self.out_dir = Path(out_dir)
        self.family = family
        self.seed = int(seed)
        self.frames = int(frames)
        self.effects = validate_effects(effects)
        self.up_axis = up_axis
        self.meters_per_unit = float(meters_per_unit)
        self.up = np.array([0.0, 1.0, 0.0]) if up_axis == "Y" else np.array([0.0, 0.0, 1.0])
        self.aspect = 1.0  # image width / height, for the camera's verticalAperture
        self.camera_poses: np.ndarray | None = None
        self._textures: dict[str, np.ndarray] = {}
        self._names: set[str] = set()

        self.stage = Usd.Stage.CreateInMemory()
        UsdGeom.SetStageUpAxis(self.stage, UsdGeom.Tokens.y if up_axis == "Y" else UsdGeom.Tokens.z)
        UsdGeom.SetStageMetersPerUnit(self.stage, self.meters_per_unit)
        self.stage.SetStartTimeCode(0)
        self.stage.SetEndTimeCode(self.frames - 1)
        self.stage.SetTimeCodesPerSecond(FPS)
        self.stage.SetFramesPerSecond(FPS)
        world = UsdGeom.Xform.Define(self.stage, "/World")
        self.stage.SetDefaultPrim(world.GetPrim())
        UsdGeom.Scope.Define(self.stage, "/World/Looks")
        UsdGeom.Xform.Define(self.stage, "/World/Geometry")
        UsdGeom.Xform.Define(self.stage, "/World/Lights")

    # ------------------------------------------------------------------ naming and placement

    def _path(self, parent: str, name: str) -> str:
        path = f"{parent}/{_sanitize(name)}"
        if path in self._names:
            raise ValueError(f"prim {path} authored twice")
        self._names.add(path)
        return path

    @staticmethod
    def place(xformable, translate=None, rotate=None, scale=None) -> None:
        """Author translate, rotateXYZ (degrees), scale ops, in that order (only those given)."""
        xf = UsdGeom.Xformable(xformable)
        if translate is not None:
            xf.AddTranslateOp().Set(_vec3d(translate))
        if rotate is not None:
            xf.AddRotateXYZOp().Set(_vec3f(rotate))
        if scale is not None:
            s = (scale, scale, scale) if np.isscalar(scale) else scale
            xf.AddScaleOp().Set(_vec3f(s))

    @staticmethod
    def place_matrix(xformable, matrix: np.ndarray) -> None:
        """Author one static ``xformOp:transform`` (row-vector 4×4, USD convention)."""
        UsdGeom.Xformable(xformable).AddTransformOp().Set(_matrix(matrix))

    # ------------------------------------------------------------------ textures and materials

    def texture(self, name: str, rgb: np.ndarray) -> str:
        """Register ``textures/<name>.png`` (written by :meth:`save`); returns the relative asset path."""
        name = _sanitize(name)
        if name in self._textures:
            raise ValueError(f"texture {name} registered twice")
        self._textures[name] = np.asarray(rgb)
        return f"{TEXTURE_DIR}/{name}.png"

    def material(
        self,
        name: str,
        diffuse=(0.7, 0.7, 0.7),
        roughness: float = 0.8,
        metallic: float = 0.0,
        ior: float = 1.5,
        opacity: float = 1.0,
        emissive=None,
        diffuse_texture: str | None = None,
        roughness_texture: str | None = None,
    ) -> UsdShade.Material:
        """A UsdPreviewSurface material; textures are relative asset paths from :meth:`texture`.

        Every input the translator reads is authored explicitly (no reliance on schema defaults).
        ``roughness_texture`` feeds ``inputs:roughness`` from the texture's ``.r`` output; the
        constant ``roughness`` stays authored as the fallback.
        """
        path = self._path("/World/Looks", name)
        mat = UsdShade.Material.Define(self.stage, path)
        shader = UsdShade.Shader.Define(self.stage, f"{path}/PreviewSurface")
        shader.CreateIdAttr("UsdPreviewSurface")
        shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(_color(diffuse))
        shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(_r(roughness))
        shader.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(_r(metallic))
        shader.CreateInput("ior", Sdf.ValueTypeNames.Float).Set(_r(ior))
        shader.CreateInput("opacity", Sdf.ValueTypeNames.Float).Set(_r(opacity))
        shader.CreateInput("emissiveColor", Sdf.ValueTypeNames.Color3f).Set(
            _color(emissive if emissive is not None else 0.0)
        )
        mat.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
        if diffuse_texture or roughness_texture:
            reader = UsdShade.Shader.Define(self.stage, f"{path}/StReader")
            reader.CreateIdAttr("UsdPrimvarReader_float2")
            reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
            reader_out = reader.CreateOutput("result", Sdf.ValueTypeNames.Float2)
            if diffuse_texture:
                tex = self._uv_texture(f"{path}/DiffuseTexture", diffuse_texture, reader_out, "sRGB")
                shader.GetInput("diffuseColor").ConnectToSource(tex.CreateOutput("rgb", Sdf.ValueTypeNames.Float3))
            if roughness_texture:
                tex = self._uv_texture(f"{path}/RoughnessTexture", roughness_texture, reader_out, "raw")
                shader.GetInput("roughness").ConnectToSource(tex.CreateOutput("r", Sdf.ValueTypeNames.Float))
        return mat

    def _uv_texture(self, path: str, asset: str, st_source, color_space: str) -> UsdShade.Shader:
        name = Path(asset).stem
        if name not in self._textures:
            raise ValueError(f"texture {asset} is not registered (call SceneBuilder.texture first)")
        tex = UsdShade.Shader.Define(self.stage, path)
        tex.CreateIdAttr("UsdUVTexture")
        tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(Sdf.AssetPath(asset))
        tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(st_source)
        tex.CreateInput("wrapS", Sdf.ValueTypeNames.Token).Set("repeat")
        tex.CreateInput("wrapT", Sdf.ValueTypeNames.Token).Set("repeat")
        tex.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set(color_space)
        return tex

    @staticmethod
    def bind(prim, material: UsdShade.Material) -> None:
        prim = prim.GetPrim() if hasattr(prim, "GetPrim") else prim
        UsdShade.MaterialBindingAPI.Apply(prim).Bind(material)

    # ------------------------------------------------------------------ geometry

    def mesh(
        self,
        name: str,
        data: MeshData,
        material: UsdShade.Material,
        double_sided: bool = False,
        translate=None,
        rotate=None,
        scale=None,
        parent: str = "/World/Geometry",
    ) -> UsdGeom.Mesh:
        mesh = UsdGeom.Mesh.Define(self.stage, self._path(parent, name))
        pts = np.round(np.asarray(data.points, dtype=np.float64), _DECIMALS) + 0.0
        mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(pts.astype(np.float32)))
        mesh.CreateFaceVertexCountsAttr(Vt.IntArray([int(c) for c in data.counts]))
        mesh.CreateFaceVertexIndicesAttr(Vt.IntArray([int(i) for i in data.indices]))
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        mesh.CreateDoubleSidedAttr(bool(double_sided))
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        mesh.CreateExtentAttr(Vt.Vec3fArray([_vec3f(lo), _vec3f(hi)]))
        if data.normals is not None:
            nrm = np.round(np.asarray(data.normals, dtype=np.float64), _DECIMALS) + 0.0
            mesh.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(nrm.astype(np.float32)))
            mesh.SetNormalsInterpolation(
                UsdGeom.Tokens.vertex if data.normals_interpolation == "vertex" else UsdGeom.Tokens.faceVarying
            )
        if data.st is not None:
            interp = UsdGeom.Tokens.vertex if data.st_interpolation == "vertex" else UsdGeom.Tokens.faceVarying
            pv = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, interp)
            st = np.round(np.asarray(data.st, dtype=np.float64), _DECIMALS) + 0.0
            pv.Set(Vt.Vec2fArray.FromNumpy(st.astype(np.float32)))
        self.place(mesh, translate, rotate, scale)
        self.bind(mesh, material)
        return mesh

    def subset(
        self, mesh: UsdGeom.Mesh, name: str, faces, material: UsdShade.Material, family_type: str = "nonOverlapping"
    ) -> UsdGeom.Subset:
        """A ``materialBind`` GeomSubset of ``mesh``'s faces, bound to ``material``.

        ``family_type`` is "nonOverlapping" (faces outside every subset keep the mesh's own
        binding) or "partition" (the subsets cover every face exactly once).
        """
        subset = UsdGeom.Subset.CreateGeomSubset(
            mesh, _sanitize(name), UsdGeom.Tokens.face, Vt.IntArray([int(f) for f in faces]), "materialBind"
        )
        UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).SetMaterialBindSubsetsFamilyType(family_type)
        self.bind(subset, material)
        return subset

    def _gprim(self, schema, name, material, translate, rotate, scale, double_sided=False):
        prim = schema.Define(self.stage, self._path("/World/Geometry", name))
        prim.CreateDoubleSidedAttr(bool(double_sided))
        self.place(prim, translate, rotate, scale)
        self.bind(prim, material)
        return prim

    def sphere(self, name, radius, material, translate=None, rotate=None, scale=None) -> UsdGeom.Sphere:
        s = self._gprim(UsdGeom.Sphere, name, material, translate, rotate, scale)
        s.CreateRadiusAttr(_r(radius))
        s.CreateExtentAttr(Vt.Vec3fArray([_vec3f([-radius] * 3), _vec3f([radius] * 3)]))
        return s

    def cube(self, name, size, material, translate=None, rotate=None, scale=None) -> UsdGeom.Cube:
        c = self._gprim(UsdGeom.Cube, name, material, translate, rotate, scale)
        c.CreateSizeAttr(_r(size))
        h = 0.5 * size
        c.CreateExtentAttr(Vt.Vec3fArray([_vec3f([-h] * 3), _vec3f([h] * 3)]))
        return c

    def cylinder(
        self, name, radius, height, axis, material, translate=None, rotate=None, scale=None
    ) -> UsdGeom.Cylinder:
        c = self._gprim(UsdGeom.Cylinder, name, material, translate, rotate, scale)
        c.CreateRadiusAttr(_r(radius))
        c.CreateHeightAttr(_r(height))
        c.CreateAxisAttr(axis)
        ext = np.full(3, radius, dtype=np.float64)
        ext["XYZ".index(axis)] = 0.5 * height
        c.CreateExtentAttr(Vt.Vec3fArray([_vec3f(-ext), _vec3f(ext)]))
        return c

    def plane(
        self, name, width, length, axis, material, translate=None, rotate=None, scale=None, double_sided=True
    ) -> UsdGeom.Plane:
        p = self._gprim(UsdGeom.Plane, name, material, translate, rotate, scale, double_sided=double_sided)
        p.CreateWidthAttr(_r(width))
        p.CreateLengthAttr(_r(length))
        p.CreateAxisAttr(axis)
        return p

    # ------------------------------------------------------------------ lights

    def _light(self, schema, name, intensity, color, exposure, translate, rotate, matrix):
        light = schema.Define(self.stage, self._path("/World/Lights", name))
        light.CreateIntensityAttr(_r(intensity))
        light.CreateExposureAttr(_r(exposure))
        light.CreateColorAttr(_color(color))
        if matrix is not None:
            self.place_matrix(light, matrix)
        else:
            self.place(light, translate, rotate)
        return light

    def aim(self, eye, target) -> np.ndarray:
        """Matrix placing a light (or anything facing −Z) at ``eye`` facing ``target``."""
        return look_at(eye, target, self.up)

    def rect_light(
        self, name, width, height, intensity, color=(1, 1, 1), exposure=0.0, translate=None, rotate=None, matrix=None
    ):
        light = self._light(UsdLux.RectLight, name, intensity, color, exposure, translate, rotate, matrix)
        light.CreateWidthAttr(_r(width))
        light.CreateHeightAttr(_r(height))
        return light

    def sphere_light(self, name, radius, intensity, color=(1, 1, 1), exposure=0.0, translate=None):
        light = self._light(UsdLux.SphereLight, name, intensity, color, exposure, translate, None, None)
        light.CreateRadiusAttr(_r(radius))
        light.CreateTreatAsPointAttr(False)
        return light

    def disk_light(
        self, name, radius, intensity, color=(1, 1, 1), exposure=0.0, translate=None, rotate=None, matrix=None
    ):
        light = self._light(UsdLux.DiskLight, name, intensity, color, exposure, translate, rotate, matrix)
        light.CreateRadiusAttr(_r(radius))
        return light

    def distant_light(self, name, angle_deg, intensity, color=(1, 1, 1), exposure=0.0, direction=None, rotate=None):
        """A sun; ``direction`` (world, the way light travels) is turned into an aim matrix."""
        matrix = None
        if direction is not None:
            d = np.asarray(direction, dtype=np.float64)
            matrix = self.aim(np.zeros(3), d)
        light = self._light(UsdLux.DistantLight, name, intensity, color, exposure, None, rotate, matrix)
        light.CreateAngleAttr(_r(angle_deg))
        return light

    def dome_light(self, name, intensity, color=(1, 1, 1), exposure=0.0, texture: str | None = None):
        """An environment; ``texture`` is a relative asset path (equirectangular, top row = up)."""
        light = self._light(UsdLux.DomeLight, name, intensity, color, exposure, None, None, None)
        if texture is not None:
            if Path(texture).stem not in self._textures:
                raise ValueError(f"texture {texture} is not registered")
            light.CreateTextureFileAttr(Sdf.AssetPath(texture))
            light.CreateTextureFormatAttr(UsdLux.Tokens.latlong)
        if self.up_axis == "Z" and hasattr(light, "CreatePoleAxisAttr"):
            light.CreatePoleAxisAttr(UsdLux.Tokens.scene)
        return light

    # ------------------------------------------------------------------ camera

    def camera(
        self,
        poses: np.ndarray,
        focal_length_mm: float = 35.0,
        horizontal_aperture_mm: float = 36.0,
        aspect: float | None = None,
        clipping=(0.05, 1000.0),
        fstop: float = 0.0,
        focus_distance: float = 0.0,
        shutter=(0.0, 0.0),
        name: str = "Camera",
    ) -> UsdGeom.Camera:
        """``/World/Camera`` with one ``xformOp:transform`` time-sampled at frames 0..F-1.

        Lens and filmback are given in millimeters and written in UsdGeomCamera's units, tenths
        of a scene unit (so 50 mm is 0.5 on a meter stage and 50 on a centimeter stage): the
        thin-lens aperture ``focalLength / (2 fStop)`` then comes out in physical size.
        ``aspect`` is width / height of the image; distances (clipping, focus) are in stage units.
        """
        tenths = 100.0 * self.meters_per_unit  # millimeters per tenth of a scene unit
        aspect = self.aspect if aspect is None else aspect
        poses = np.asarray(poses, dtype=np.float64)
        if poses.shape != (self.frames, 4, 4):
            raise ValueError(f"camera poses must be {self.frames}×4×4, got {poses.shape}")
        cam = UsdGeom.Camera.Define(self.stage, self._path("/World", name))
        cam.CreateProjectionAttr(UsdGeom.Tokens.perspective)
        cam.CreateFocalLengthAttr(_r(focal_length_mm / tenths))
        cam.CreateHorizontalApertureAttr(_r(horizontal_aperture_mm / tenths))
        cam.CreateVerticalApertureAttr(_r(horizontal_aperture_mm / aspect / tenths))
        cam.CreateClippingRangeAttr(Gf.Vec2f(_r(clipping[0]), _r(clipping[1])))
        cam.CreateFStopAttr(_r(fstop))
        cam.CreateFocusDistanceAttr(_r(focus_distance))
        cam.CreateShutterOpenAttr(_r(shutter[0]))
        cam.CreateShutterCloseAttr(_r(shutter[1]))
        op = cam.AddTransformOp()
        for f in range(self.frames):
            op.Set(_matrix(poses[f]), Usd.TimeCode(f))
        self.camera_poses = poses
        return cam

    # ------------------------------------------------------------------ output

    def _check(self) -> None:
        for prim in self.stage.Traverse():
            if prim.IsA(UsdGeom.Gprim):
                bound, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
                if not bound:
                    raise RuntimeError(f"{self.family}: {prim.GetPath()} has no bound material")
        if not self.stage.GetPrimAtPath("/World/Camera"):
            raise RuntimeError(f"{self.family}: no /World/Camera")

    def save(self) -> Path:
        """Write the textures and ``scene.usda`` into ``out_dir``; return the stage path.

        Files are written under temporary names and renamed. PNGs in ``out_dir/textures`` that
        this stage does not reference are removed, so the folder always matches the stage.
        """
        self._check()
        self.stage.GetRootLayer().customLayerData = {
            METADATA_KEY: {
                "family": self.family,
                "seed": self.seed,
                "effects": Vt.StringArray(list(self.effects)),
                "frames": self.frames,
            }
        }
        self.out_dir.mkdir(parents=True, exist_ok=True)
        tex_dir = self.out_dir / TEXTURE_DIR
        # textures/ belongs to the stage: PNGs of an earlier authoring (another seed) go away.
        if tex_dir.is_dir():
            for stale in sorted(tex_dir.glob("*.png")):
                if stale.stem not in self._textures:
                    stale.unlink()
        for name in sorted(self._textures):
            write_png(tex_dir / f"{name}.png", self._textures[name])
        path = self.out_dir / STAGE_FILENAME
        text = self.stage.GetRootLayer().ExportToString()
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(text, encoding="utf-8")
        tmp.replace(path)
        return path
