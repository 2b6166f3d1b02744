/*
 * export_bmfr.h — frames in the input layout of the published OpenCL BMFR
 * code (Koskela et al. 2019, github.com/maZZZu/bmfr), so that the reference
 * implementation runs on exactly hush's frames (bmfr-koskela-2019.md §6).
 *
 * Into a directory:
 *   colorN.exr           demodulated radiance: color / albedo
 *   albedoN.exr          the albedo that remodulates it
 *   shading_normalN.exr  world shading normal
 *   world_positionN.exr  world position
 * N = 0, 1, ... (no zero padding: the code appends std::to_string(frame));
 * each file has exactly 3 float channels R, G, B (the code refuses any other
 * count), row 0 at the top.
 *
 * Demodulation guard: an albedo channel below HUSH_BMFR_MIN_ALBEDO (black
 * surfaces, and the holes of the progressive mode) is written as 1 and the
 * colour channel is left undivided, so colorN * albedoN is the radiance
 * again wherever the albedo was 0.
 *
 * Sky pixels (nothing hit: normal 0, position 0; the renderer's albedo is 1
 * there) are demodulated by their own radiance: colorN = 1, albedoN = the
 * radiance (the guard applies to channels below HUSH_BMFR_MIN_ALBEDO). The
 * code fits colour in 32x32 blocks by least squares on normal and position
 * features, which cannot tell the sky from a surface at the origin: sky
 * radiance, orders of magnitude above the room's, leaked into the fit of
 * every block with a window (and the sky's history, looked up where the
 * origin projects, came from the wrong place). A radiance seen directly is
 * not noisy, so this is exact for the sky and keeps it out of the fit:
 * classroom 640x360, relMSE 0.564 -> 0.544 (docs/bmfr-reference.md).
 *
 *   camera_matrices.h    the C header the code #includes:
 *     const float position_limit_squared, normal_limit_squared;  (reprojection tests)
 *     const float camera_matrices[N][4][4];  view-projection per frame
 *     const float pixel_offsets[N][2];       the sample's place in its pixel
 *
 * camera_matrices[i] is view_to_clip * world_to_view of frame i, without
 * jitter, stored column-major: camera_matrices[i][c][r] is row r of column
 * c, so that &camera_matrices[i][0][0] is hush's column-major float[16]
 * (the code loads it as an OpenCL float16 and takes rows as .s048c).
 * BMFR's NDC y is -1 at the TOP row (it maps (ndc + 1) / 2 * height straight
 * to row indices), hush's is +1 at the top, so row 1 of the matrix (clip y) is
 * negated.
 *
 * pixel_offsets[i] = (0.5 + jitter_x, 0.5 - jitter_y): where frame i's
 * sample lies inside its pixel, x to the right and y UP from the pixel's
 * bottom edge, as the code uses it: the pixel index of a projected point is
 * uv * size - (offset.x, 1 - offset.y). No jitter gives (0.5, 0.5). The code
 * pairs camera_matrices[i - 1] with pixel_offsets[i]; this frame's offset
 * cancels this frame's jitter, so its history lookup lands where hush's motion
 * vectors point. Checked by running the published code (commit 4b821c6,
 * tools/run-bmfr-reference.sh, docs/bmfr-reference.md).
 */
#ifndef HUSH_IO_EXPORT_BMFR_H
#define HUSH_IO_EXPORT_BMFR_H

#include "hush.h"
#include "io/sequence.h"

#include <stdint.h>

#define HUSH_BMFR_MIN_ALBEDO 1e-3f

/* Defaults of the two reprojection thresholds written to camera_matrices.h:
 * those of the BMFR data set's classroom scene (squared world distance, and
 * squared distance of unit normals). Scene-scale dependent: edit the header
 * for other scenes. */
#define HUSH_BMFR_POSITION_LIMIT_SQUARED 0.01f
#define HUSH_BMFR_NORMAL_LIMIT_SQUARED 1.0f

/* Writes frame `index` (layers color, albedo, normal, position) as the four
 * EXRs in dir (which must exist). */
hush_status hush__bmfr_write_frame(hush_device device, const char *dir, uint32_t index,
                                   hush_frame frame);

/* BMFR's view-projection matrix of a camera (column-major, y flipped). */
void hush__bmfr_matrix(const hush_camera *camera, float out[16]);

/* BMFR's pixel offset of a camera's jitter. */
void hush__bmfr_pixel_offset(const hush_camera *camera, float out[2]);

/* Writes dir/camera_matrices.h for cameras[0 .. count-1]. */
hush_status hush__bmfr_write_cameras(hush_device device, const char *dir,
                                     const hush_camera *cameras, uint32_t count,
                                     float position_limit_squared, float normal_limit_squared);

#endif
