"""The GLSL likelihood statistics: shader sources and the arrays they read, without bpy.

The GPU host (addon/gpu_likelihood.py, where bpy's `gpu` module is allowed) compiles these shaders and
feeds them the arrays packed here. Three passes per batch of poses, all pose-views in one draw each:

1. draw: the proxy, unrolled to one vertex per triangle corner (so the part label is a per-vertex
   attribute), instanced once per pose-view tile of an atlas. The vertex shader skins the rest vertex
   with the pose's bone matrices (a texture, 3 texels per bone per pose), projects it with the view's
   OpenCV camera (a texture, lens distortion included), and places it in the tile; the fragment shader
   writes the part label and discards pixels outside the tile. Depth is Z_NEAR / z, linear in screen
   space like the reference's interpolated 1/z, so the depth test keeps the same surface.
2. rows: one fragment per (tile, image row) walks the row and sums the per-pixel statistics
   (template, overlap, boundary, boundary off an edge, the silhouette and edge distance sums).
3. tiles: one fragment per tile sums its rows. Only 8 floats per pose-view are read back.

Pixel rows are image rows (y down), so texel (x, y) of a tile is pixel (row y, column x) of the image
the reference rasterises; the rasteriser's sampling points and the reference's differ only on pixel
centres that lie exactly on a triangle edge (the top-left rule's y direction), a few pixels per image.
The statistics not computed here (the template's chamfer transform for SUM_DT, colour histograms) come
from the CPU path.
"""
from __future__ import annotations

import numpy as np

from .reference import BOUNDARY, BOUNDARY_OFF, OVERLAP, SUM_DI, SUM_EDGE_DT, TEMPLATE, Z_NEAR

# Atlas side: on a software rasteriser, ~200 tiles of 320x240 per draw with label and depth textures of
# 64 MB each; on a GPU, a whole batch of 200 poses x 4 views in one draw (256 MB each) [DESIGN].
ATLAS_SIDE = 4096
ATLAS_SIDE_GPU = 8192
CAMERA_TEXELS = 8  # R|t (3 texels), fx fy cx cy, skew + distortion flag, 12 distortion coefficients (3 texels)
# Order of the 8 floats the tile pass writes per pose-view (two RGBA targets).
READBACK_COLUMNS = (TEMPLATE, OVERLAP, BOUNDARY, BOUNDARY_OFF, SUM_DI, SUM_EDGE_DT)


class GlslInputError(ValueError):
    """The mesh, cameras or targets cannot be packed for the GLSL path."""


# ---------------------------------------------------------------------------------------- packing
def influence_slots(weights):
    """How many vec4 (bone, weight) slots per vertex hold every non-zero skin weight."""
    most = int((np.asarray(weights) > 0).sum(axis=1).max()) if len(weights) else 1
    return max(1, -(-most // 4))


def pack_mesh(vertices, weights, unweighted, faces, face_label, n_bones):
    """The proxy as an indexed mesh whose vertices carry their triangle's part label: a vertex shared by
    triangles of different parts is repeated once per part (the label must not be interpolated).

    Returns (attributes, indices): float32 arrays 'rest' (N,3), 'label' (N,), 'bone{k}' / 'weight{k}' (N,4)
    for each influence slot, and (F,3) int32 corner indices in the proxy's triangle order (the depth
    test's ties keep the first-drawn triangle, as the reference's lowest index). Unweighted vertices point
    at bone index n_bones, the armature matrix (they stay where the rest mesh is, as in
    body.blend_vertices)."""
    vertices = np.asarray(vertices, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if weights.shape != (len(vertices), n_bones):
        raise GlslInputError(f"skin weights have shape {weights.shape}; expected {(len(vertices), n_bones)}")
    slots = influence_slots(weights)
    order = np.argsort(-weights, axis=1, kind="stable")[:, :4 * slots]
    w = np.take_along_axis(weights, order, axis=1)
    idx = np.where(w > 0, order, 0).astype(np.float32)
    w = w.astype(np.float32)
    static = np.asarray(unweighted, dtype=bool) if unweighted is not None else np.zeros(len(vertices), bool)
    idx[static] = 0
    idx[static, 0] = n_bones
    w[static] = 0
    w[static, 0] = 1
    labels = np.asarray(face_label, dtype=np.int64)
    corner_keys = np.stack([faces.reshape(-1), np.repeat(labels, 3)], axis=1)
    keys, inverse = np.unique(corner_keys, axis=0, return_inverse=True)
    source = keys[:, 0]
    out = {"rest": vertices[source].astype(np.float32), "label": keys[:, 1].astype(np.float32)}
    for k in range(slots):
        out[f"bone{k}"] = np.ascontiguousarray(idx[source, 4 * k:4 * k + 4])
        out[f"weight{k}"] = np.ascontiguousarray(w[source, 4 * k:4 * k + 4])
    return out, inverse.reshape(-1, 3).astype(np.int32)


def pack_bones(skin_matrices, armature_matrix):
    """(P,B,4,4) skinning matrices -> (P, 3*(B+1), 4) float32 texture rows: the top three rows of every
    bone's matrix, then the armature matrix (for unweighted vertices)."""
    M = np.asarray(skin_matrices, dtype=np.float64)
    P, B = M.shape[:2]
    out = np.empty((P, B + 1, 3, 4), dtype=np.float32)
    out[:, :B] = M[:, :, :3, :]
    out[:, B] = np.asarray(armature_matrix, dtype=np.float64)[:3, :]
    return out.reshape(P, 3 * (B + 1), 4)


def pack_cameras(cameras):
    """Cameras -> (C, CAMERA_TEXELS, 4) float32: R rows with t in w, (fx, fy, cx, cy), (skew, flag, 0, 0),
    then the 12 OpenCV distortion coefficients; flag 1 when there is any distortion."""
    out = np.zeros((len(cameras), CAMERA_TEXELS, 4), dtype=np.float32)
    for c, cam in enumerate(cameras):
        out[c, :3, :3] = cam.R
        out[c, :3, 3] = cam.t
        K = cam.K
        out[c, 3] = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
        out[c, 4, 0] = K[0, 1]
        dist = np.zeros(12)
        dist[:cam.dist.size] = cam.dist
        out[c, 4, 1] = float(np.any(dist))
        out[c, 5:8] = dist.reshape(3, 4)
    return out


def pack_targets(targets):
    """FrameTargets -> (C*H, W, 4) float32, views stacked downwards: silhouette, E_v (0 on image edges),
    distance to the observed silhouette, truncated edge distance."""
    C, H, W = targets.silhouette.shape
    out = np.empty((C, H, W, 4), dtype=np.float32)
    out[..., 0] = targets.silhouette
    out[..., 1] = targets.edge_off
    out[..., 2] = targets.silhouette_dt
    out[..., 3] = targets.edge_dt
    return out.reshape(C * H, W, 4)


def bone_spheres(vertices, weights, unweighted):
    """Per bone (and one more for the unweighted vertices, moved by the armature matrix): the centre (rest)
    and radius of a sphere holding every vertex the bone moves. A skinned vertex is a weighted mean of its
    bones' rigid images of it, so it lies in the convex hull of those bones' moved spheres."""
    vertices = np.asarray(vertices, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    static = np.asarray(unweighted, dtype=bool) if unweighted is not None else np.zeros(len(vertices), bool)
    centres = np.zeros((weights.shape[1] + 1, 3))
    radii = np.full(weights.shape[1] + 1, -1.0)  # -1: moves no vertex
    for b, members in enumerate(list((weights > 0).T & ~static) + [static]):
        if members.any():
            pts = vertices[members]
            centres[b] = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
            radii[b] = np.linalg.norm(pts - centres[b], axis=1).max()
    return centres, radii


def tile_boxes(skin_matrices, armature_matrix, centres, radii, cameras, widths, heights):
    """(P,C,4) float32 pixel box x0, y0, x1, y1 (inclusive) that holds the pose's template in each view,
    from the bones' spheres (bone_spheres): the reduction passes scan only these pixels. A view with lens
    distortion, or a sphere reaching the camera plane, gets the whole image."""
    M = np.asarray(skin_matrices, dtype=np.float64)
    P, B = M.shape[:2]
    M = np.concatenate([M, np.broadcast_to(np.asarray(armature_matrix, dtype=np.float64), (P, 1, 4, 4))], axis=1)
    used = radii >= 0
    M, centres, radii = M[:, used], centres[used], radii[used]
    world = np.einsum("pbij,bj->pbi", M[..., :3, :3], centres) + M[..., :3, 3]  # (P,B',3)
    # How much a bone may stretch a sphere: sqrt of the Gram matrix's largest eigenvalue, bounded by its
    # largest absolute row sum (Gershgorin); exactly 1 for rigid bones, and no SVD per bone.
    A = M[..., :3, :3]
    gram = np.einsum("pbji,pbjk->pbik", A, A)
    stretch = np.sqrt(np.abs(gram).sum(axis=-1).max(axis=-1))
    r = radii[None] * stretch
    boxes = np.zeros((P, len(cameras), 4), dtype=np.float32)
    for c, cam in enumerate(cameras):
        w, h = int(widths[c]), int(heights[c])
        boxes[:, c] = 0, 0, w - 1, h - 1
        if cam.has_distortion:
            continue
        pc = world @ cam.R.T + cam.t  # (P,B',3)
        z_lo = pc[..., 2] - r
        ok = np.all(z_lo > 1e-6, axis=1)
        # u and v are linear-fractional in (x, y, z), so over the sphere's box their extremes are at corners
        X = np.stack([pc[..., 0] - r, pc[..., 0] + r], axis=-1)[..., :, None, None]
        Y = np.stack([pc[..., 1] - r, pc[..., 1] + r], axis=-1)[..., None, :, None]
        Z = np.stack([np.maximum(z_lo, 1e-6), pc[..., 2] + r], axis=-1)[..., None, None, :]
        K = cam.K
        u = (K[0, 0] * X + K[0, 1] * Y) / Z + K[0, 2]
        v = K[1, 1] * Y / Z + K[1, 2]
        axes = (1, 2, 3, 4)
        u_lo, u_hi, v_lo, v_hi = u.min(axis=axes), u.max(axis=axes), v.min(axis=axes), v.max(axis=axes)
        box = np.stack([np.floor(u_lo) - 1, np.floor(v_lo) - 1, np.ceil(u_hi) + 1, np.ceil(v_hi) + 1], axis=1)
        box = np.clip(box, 0, [w - 1, h - 1, w - 1, h - 1])
        boxes[ok, c] = box[ok]
    return boxes


BOX_ROW = 1024  # tile boxes per texture row


def pack_boxes(boxes):
    """(P,C,4) tile boxes -> (rows, BOX_ROW, 4) float32 texture rows, tile = pose * C + view."""
    flat = np.asarray(boxes, dtype=np.float32).reshape(-1, 4)
    out = np.zeros((-(-len(flat) // BOX_ROW) * BOX_ROW, 4), dtype=np.float32)
    out[:len(flat)] = flat
    return out.reshape(-1, BOX_ROW, 4)


def atlas_layout(n_tiles, tile_w, tile_h, side=ATLAS_SIDE):
    """Tiles per row and rows per atlas draw, and how many tiles one atlas holds."""
    if tile_w > side or tile_h > side:
        raise GlslInputError(f"an energy image of {tile_w}x{tile_h} does not fit the GPU atlas ({side} px); "
                             "lower the energy resolution")
    per_row = max(1, side // tile_w)
    rows = max(1, min(side // tile_h, -(-n_tiles // per_row)))
    return per_row, rows, per_row * rows


def unpack_statistics(readback, P, C, n_stats):
    """(n_tiles, 8) floats of the tile pass, tile = pose * C + view -> (P, C, n_stats) statistics."""
    stats = np.zeros((P, C, n_stats))
    r = np.asarray(readback, dtype=np.float64).reshape(P, C, 8)
    for k, column in enumerate(READBACK_COLUMNS):
        stats[..., column] = r[..., k]
    return stats


# ---------------------------------------------------------------------------------------- GLSL
def draw_vertex_source(slots):
    """Skin, project, place in the tile. `slots` influence vec4s per vertex (see pack_mesh)."""
    blend = "\n".join(
        f"  for (int i = 0; i < 4; i++) {{ if (weight{k}[i] > 0.0) {{ int b = int(bone{k}[i] + 0.5);"
        f" m0 += weight{k}[i] * bone_row(pose, b, 0); m1 += weight{k}[i] * bone_row(pose, b, 1);"
        f" m2 += weight{k}[i] * bone_row(pose, b, 2); }} }}"
        for k in range(slots))
    return """
vec4 bone_row(int pose, int b, int r) { return texelFetch(bones, ivec2(3 * b + r, pose), 0); }
vec4 cam(int view, int k) { return texelFetch(cameras, ivec2(k, view), 0); }

void main() {
  label_v = label;
  int tile = gl_InstanceID + first_tile;
  int pose = tile / n_views;
  int view = tile - pose * n_views;
  vec4 m0 = vec4(0.0), m1 = vec4(0.0), m2 = vec4(0.0);
""" + blend + """
  vec4 p = vec4(rest, 1.0);
  vec3 world = vec3(dot(m0, p), dot(m1, p), dot(m2, p));
  vec4 r0 = cam(view, 0), r1 = cam(view, 1), r2 = cam(view, 2), k = cam(view, 3), k2 = cam(view, 4);
  vec3 pc = vec3(dot(r0.xyz, world) + r0.w, dot(r1.xyz, world) + r1.w, dot(r2.xyz, world) + r2.w);
  float x = pc.x / pc.z, y = pc.y / pc.z;
  if (k2.y > 0.0) {  /* OpenCV's lens model, as Camera._distort */
    vec4 d0 = cam(view, 5), d1 = cam(view, 6), d2 = cam(view, 7);
    float r2_ = x * x + y * y, r4 = r2_ * r2_;
    float radial = (1.0 + r2_ * (d0.x + r2_ * (d0.y + r2_ * d1.x))) / (1.0 + r2_ * (d1.y + r2_ * (d1.z + r2_ * d1.w)));
    float xy2 = 2.0 * x * y;
    float xd = x * radial + d0.z * xy2 + d0.w * (r2_ + 2.0 * x * x) + d2.x * r2_ + d2.y * r4;
    float yd = y * radial + d0.z * (r2_ + 2.0 * y * y) + d0.w * xy2 + d2.z * r2_ + d2.w * r4;
    x = xd; y = yd;
  }
  float u = k.x * x + k2.x * y + k.z;
  float v = k.y * y + k.w;
  int col = tile - first_tile;
  int tx = col - (col / tiles_per_row) * tiles_per_row;
  int ty = col / tiles_per_row;
  vec2 origin = vec2(float(tx * tile_w), float(ty * tile_h));
  tile_box = vec4(origin, origin + vec2(texelFetch(sizes, ivec2(view, 0), 0).xy));
  vec2 window = origin + vec2(u, v) + 0.5;  /* pixel (row i, column j) is sampled at (j, i) */
  near = pc.z > near_z ? 0.0 : 1.0;
  gl_Position = vec4(window / atlas_size * 2.0 - 1.0, 1.0 - 2.0 * clamp(near_z / pc.z, 0.0, 1.0), 1.0);
}
"""


DRAW_FRAGMENT_SOURCE = """
void main() {
  /* a triangle with a corner at or behind the near plane is not drawn (reference: Z_NEAR) */
  if (near > 0.0) discard;
  vec2 p = gl_FragCoord.xy;
  if (p.x < tile_box.x || p.y < tile_box.y || p.x >= tile_box.z || p.y >= tile_box.w) discard;
  if (cull != 0 && (gl_FrontFacing ? 1 : -1) != cull) discard;
  label_out = vec4(label_v, 0.0, 0.0, 1.0);
}
"""

ROWS_FRAGMENT_SOURCE = f"""
#define BOX_ROW {BOX_ROW}
float lab(ivec2 p) {{ return texelFetch(labels, p, 0).r; }}

void main() {{
  int tile = int(gl_FragCoord.x) + first_tile;
  int row = int(gl_FragCoord.y);
  int pose = tile / n_views;
  int view = tile - pose * n_views;
  ivec2 size = ivec2(texelFetch(sizes, ivec2(view, 0), 0).xy);
  vec4 counts = vec4(0.0);
  vec4 sums = vec4(0.0);
  vec4 box = texelFetch(boxes, ivec2(tile % BOX_ROW, tile / BOX_ROW), 0);  /* holds the template (tile_boxes) */
  if (row < size.y && float(row) >= box.y && float(row) <= box.w) {{
    int col = tile - first_tile;
    int tx = col - (col / tiles_per_row) * tiles_per_row;
    int ty = col / tiles_per_row;
    ivec2 origin = ivec2(tx * tile_w, ty * tile_h + row);
    int obs_row = view * tile_h + row;
    for (int x = int(box.x); x <= int(box.z); x++) {{
      float l = lab(origin + ivec2(x, 0));
      if (l <= 0.0) continue;
      vec4 obs = texelFetch(observed, ivec2(x, obs_row), 0);
      bool edge = (x > 0 && lab(origin + ivec2(x - 1, 0)) != l)
               || (x + 1 < size.x && lab(origin + ivec2(x + 1, 0)) != l)
               || (row > 0 && lab(origin + ivec2(x, -1)) != l)
               || (row + 1 < size.y && lab(origin + ivec2(x, 1)) != l);
      counts += vec4(1.0, obs.r, edge ? 1.0 : 0.0, edge ? obs.g : 0.0);
      sums += vec4(obs.b, edge ? obs.a : 0.0, 0.0, 0.0);
    }}
  }}
  counts_out = counts;
  sums_out = sums;
}}
"""

TILES_FRAGMENT_SOURCE = """
void main() {
  int tile = int(gl_FragCoord.x);
  vec4 counts = vec4(0.0);
  vec4 sums = vec4(0.0);
  for (int row = 0; row < n_rows; row++) {
    counts += texelFetch(row_counts, ivec2(tile, row), 0);
    sums += texelFetch(row_sums, ivec2(tile, row), 0);
  }
  counts_out = counts;
  sums_out = sums;
}
"""

FULLSCREEN_VERTEX_SOURCE = """
void main() { gl_Position = vec4(pos, 0.0, 1.0); }
"""

__all__ = ["ATLAS_SIDE", "ATLAS_SIDE_GPU", "GlslInputError", "influence_slots", "pack_mesh", "pack_bones",
           "pack_cameras", "pack_targets", "atlas_layout", "unpack_statistics", "draw_vertex_source",
           "DRAW_FRAGMENT_SOURCE", "ROWS_FRAGMENT_SOURCE", "TILES_FRAGMENT_SOURCE", "FULLSCREEN_VERTEX_SOURCE",
           "Z_NEAR"]
