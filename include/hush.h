/*
 * hush.h — the public C API of libhush, a library of real-time reconstruction
 * filters for noisy path-traced frames.
 *
 * Shape (after Intel Open Image Denoise and Embree):
 *   - opaque handles (hush_device, hush_filter, hush_frame) with
 *     create / retain / release;
 *   - images described by pointer, format, width, height and byte strides;
 *     the caller owns pixel memory, a filter owns its history;
 *   - parameters set by name, validated against each filter's table;
 *   - every fallible call returns a hush_status; the device keeps the first
 *     error and its message until hush_device_get_error() reads it.
 *     The library never prints.
 *
 * Threading: a device and the objects made from it must be used by one
 * thread at a time. Separate devices may be used concurrently. Filters run
 * their own worker threads (OpenMP), as many as the device's "threads".
 *
 * Conventions (used by every filter, by the frame files and by hush render):
 *   - World space is right-handed, in scene units. View space: the camera
 *     at the origin looking down -Z, +Y up, +X right (OpenGL).
 *   - Matrices are 4x4 float, column-major (element (row r, column c) at
 *     m[c * 4 + r]), applied to column vectors: p_view = W2V * p_world,
 *     p_clip = V2C * p_view. Clip space is OpenGL's: NDC in [-1, 1]^3.
 *   - Pixels: (x, y) with row 0 at the TOP of the image; pixel (x, y) covers
 *     [x, x+1) x [y, y+1) and its centre is (x + 0.5, y + 0.5).
 *     NDC y = +1 is the top edge, so  px = (ndc_x + 1) / 2 * width,
 *     py = (1 - ndc_y) / 2 * height.
 *   - Matrices exclude the subpixel jitter. The jitter is given separately,
 *     in pixels: the primary ray of pixel (x, y) went through
 *     (x + 0.5 + jitter[0], y + 0.5 + jitter[1]).
 *   - "depth" is linear view depth: the distance along the view axis,
 *     -z_view, positive in front of the camera, in world units.
 *     A pixel that hit nothing (sky) has depth 0 or +inf written as 0 and
 *     counts as background: it never accepts history from a surface.
 *   - "normal" is the world-space unit shading normal of the first hit.
 *   - "position" is the world-space position of the first hit.
 *   - "motion" is in pixels, previous minus current: the point seen at pixel
 *     centre c in this frame was at c + motion in the previous frame.
 *   - "id" holds a mesh or material id as an integer-valued float (exact up
 *     to 2^24); history is accepted only from a pixel with the same id.
 *   - "albedo" is the first-hit albedo used for demodulation: what the
 *     surface reflects, per channel in [0, 1]. For a coated or glossy
 *     material include the specular lobe's reflectance (a plastic:
 *     ks + (1 - ks) * base), not only the base colour, or its highlights
 *     are divided by the base's darkest channel. Channels below 0.02 count
 *     as 0.02. Radiance is linear, in scene-referred units (no tone
 *     mapping).
 *   - Mirrors: where the first hit is a planar mirror, describe the surface
 *     seen in it (primary surface replacement, as hush's renderer does):
 *     its position and normal reflected through the mirror's plane, its id,
 *     its albedo times the mirror's reflectance, motion of the reflection,
 *     and the light seen in the mirror in "emission". A G-buffer of the
 *     mirror itself works too, but the filters then blur the reflection
 *     across it (docs/renderer.md).
 */
#ifndef HUSH_H
#define HUSH_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* The library is built with hidden visibility; only HUSH_API symbols,
 * all named hush_*, are exported from the shared object. */
#if defined(__GNUC__)
#  define HUSH_API __attribute__((visibility("default")))
#else
#  define HUSH_API
#endif

#define HUSH_VERSION_MAJOR 0
#define HUSH_VERSION_MINOR 1
#define HUSH_VERSION_PATCH 0

/* "MAJOR.MINOR.PATCH" of the library actually loaded. */
HUSH_API const char *hush_version(void);

/* ------------------------------------------------------------------------ */
/* Status codes                                                             */
/* ------------------------------------------------------------------------ */

typedef enum hush_status {
  HUSH_OK = 0,
  HUSH_ERROR_UNKNOWN = 1,
  HUSH_ERROR_INVALID_ARGUMENT = 2,  /* NULL handle, bad size, bad stride ... */
  HUSH_ERROR_INVALID_OPERATION = 3, /* e.g. execute before commit */
  HUSH_ERROR_OUT_OF_MEMORY = 4,
  HUSH_ERROR_NOT_FOUND = 5,         /* unknown filter, parameter or image name */
  HUSH_ERROR_OUT_OF_RANGE = 6,      /* parameter value outside its range */
  HUSH_ERROR_TYPE_MISMATCH = 7,     /* e.g. set_float on an int parameter */
  HUSH_ERROR_NONFINITE = 8,         /* NaN, Inf or a value beyond +-1e15 in an input image */
  HUSH_ERROR_IO = 9,                /* file cannot be opened, read or written */
  HUSH_ERROR_CORRUPT = 10,          /* file is truncated or malformed */
  HUSH_ERROR_UNSUPPORTED = 11       /* valid file or request hush cannot handle */
} hush_status;

/* Short constant name of a status ("HUSH_ERROR_NOT_FOUND"); never NULL. */
HUSH_API const char *hush_status_name(hush_status status);

/* ------------------------------------------------------------------------ */
/* Devices                                                                  */
/* ------------------------------------------------------------------------ */

typedef struct hush_device_t *hush_device;

/*
 * Creates a device from a configuration string of comma-separated key=value
 * pairs, or NULL for the defaults:
 *   threads=N   worker threads (0 = one per core; default 0)
 *   verbose=N   0..2: how much the device reports through its log callback
 *               (default 0). The library never prints.
 *   memory=N    MiB that each filter may allocate for its buffers and
 *               history, at commit and at its first executes (default 0:
 *               the machine's memory, or the cgroup limit of the process
 *               if lower). A commit that needs more fails with
 *               HUSH_ERROR_OUT_OF_MEMORY and keeps nothing; an execute
 *               that needs more (the first frames allocate the buffers of
 *               the stages and images they use) fails with it too.
 * On failure returns NULL; hush_device_get_error(NULL, ...) tells why.
 * The caller owns the returned reference: hush_device_release() it.
 */
HUSH_API hush_device hush_device_new(const char *config);
HUSH_API void hush_device_retain(hush_device device);
/* Drops one reference; the device is freed when its filters and frames are. */
HUSH_API void hush_device_release(hush_device device);

/*
 * Reads and clears the device's first unread error. Returns HUSH_OK (and a
 * message of "") when there is none. *message, if message is not NULL, is
 * set to a NUL-terminated text owned by the device, valid until the next
 * call on the device. With device == NULL it reads the error of the last
 * failed hush_device_new() on the calling thread.
 */
HUSH_API hush_status hush_device_get_error(hush_device device, const char **message);

/* Called for every error as it happens (not only the first), from the
 * thread that made the failing call. NULL removes the callback. */
typedef void (*hush_error_fn)(void *user, hush_status status, const char *message);
HUSH_API void hush_device_set_error_callback(hush_device device, hush_error_fn fn, void *user);

/* Called with informational messages when verbose > 0. NULL removes it. */
typedef void (*hush_log_fn)(void *user, int level, const char *message);
HUSH_API void hush_device_set_log_callback(hush_device device, hush_log_fn fn, void *user);

/* Number of worker threads the device's filters use (resolved, >= 1). */
HUSH_API int hush_device_threads(hush_device device);

/* ------------------------------------------------------------------------ */
/* Image formats and views                                                  */
/* ------------------------------------------------------------------------ */

typedef enum hush_format {
  HUSH_FORMAT_UNDEFINED = 0,
  HUSH_FORMAT_FLOAT = 1, /* 32-bit IEEE float, 1 channel */
  HUSH_FORMAT_FLOAT2 = 2,
  HUSH_FORMAT_FLOAT3 = 3,
  HUSH_FORMAT_FLOAT4 = 4,
  HUSH_FORMAT_HALF = 17, /* 16-bit IEEE float (binary16), 1 channel */
  HUSH_FORMAT_HALF2 = 18,
  HUSH_FORMAT_HALF3 = 19,
  HUSH_FORMAT_HALF4 = 20
} hush_format;

/* Channels (1..4) of a format, 0 for UNDEFINED or an invalid value. */
HUSH_API int hush_format_channels(hush_format format);
/* Bytes of one pixel of the format, 0 for UNDEFINED or an invalid value. */
HUSH_API size_t hush_format_pixel_size(hush_format format);

/*
 * A view of caller-owned pixels. Pixel (x, y), channel c, is at
 *   (char *)data + byte_offset + y * row_stride + x * pixel_stride
 *   + c * (element size).
 * pixel_stride 0 means packed (hush_format_pixel_size), row_stride 0 means
 * width * pixel_stride. Strides must be multiples of the element size (4 or
 * 2 bytes) and pixels must not overlap. Row 0 is the top of the image.
 */
typedef struct hush_image_view {
  void *data;
  hush_format format;
  uint32_t width, height;
  size_t byte_offset;
  size_t pixel_stride;
  size_t row_stride;
} hush_image_view;

/* ------------------------------------------------------------------------ */
/* Filter classes and their parameter tables (static, no device needed)    */
/* ------------------------------------------------------------------------ */

typedef enum hush_param_type {
  HUSH_PARAM_BOOL = 0,
  HUSH_PARAM_INT = 1,
  HUSH_PARAM_FLOAT = 2,
  HUSH_PARAM_ENUM = 3 /* an int 0..n-1 that also has names (enum_names) */
} hush_param_type;

typedef struct hush_param_info {
  const char *name;
  hush_param_type type;
  double default_value;
  double min_value, max_value;   /* inclusive; ignored for BOOL */
  const char *doc;               /* one line */
  const char *const *enum_names; /* ENUM: max_value + 1 names; else NULL */
} hush_param_info;

typedef enum hush_image_role {
  HUSH_IMAGE_INPUT = 0,
  HUSH_IMAGE_OUTPUT = 1
} hush_image_role;

typedef struct hush_image_info {
  const char *name;        /* "color", "albedo", "normal", "output", ... */
  hush_image_role role;
  int required;            /* 1: commit fails while it is unbound */
  int channels;            /* channels the filter reads or writes */
  const char *doc;         /* one line */
} hush_image_info;

typedef struct hush_filter_class_info {
  const char *name;        /* "accumulate", ... */
  const char *doc;         /* one line */
  const char *paper;       /* the document and section it follows */
  const hush_param_info *params;
  uint32_t param_count;
  const hush_image_info *images;
  uint32_t image_count;
} hush_filter_class_info;

/* Number of filter classes this build provides. */
HUSH_API uint32_t hush_filter_class_count(void);
/* Class i (0 <= i < count) or NULL. Points at static, immutable tables. */
HUSH_API const hush_filter_class_info *hush_filter_class_at(uint32_t index);
/* Class by name or NULL. */
HUSH_API const hush_filter_class_info *hush_filter_class_find(const char *name);

/* ------------------------------------------------------------------------ */
/* Filters                                                                  */
/* ------------------------------------------------------------------------ */

typedef struct hush_filter_t *hush_filter;

/*
 * Creates a filter of the named class ("accumulate", ...). NULL and an error
 * on the device (HUSH_ERROR_NOT_FOUND) for an unknown name. The caller owns
 * the returned reference. The filter holds a reference to the device.
 */
HUSH_API hush_filter hush_filter_new(hush_device device, const char *class_name);
HUSH_API void hush_filter_retain(hush_filter filter);
HUSH_API void hush_filter_release(hush_filter filter);
/* The class the filter was made from. */
HUSH_API const hush_filter_class_info *hush_filter_get_class(hush_filter filter);

/* Parameter setters validate the name, the type and the range. A setter on a
 * committed filter takes effect at the next execute (no re-commit needed).
 * set_int is accepted for ENUM and BOOL parameters; set_float for INT
 * parameters when the value is integral. */
HUSH_API hush_status hush_filter_set_bool(hush_filter filter, const char *name, int value);
HUSH_API hush_status hush_filter_set_int(hush_filter filter, const char *name, int value);
HUSH_API hush_status hush_filter_set_float(hush_filter filter, const char *name, float value);
/* Sets any parameter from text: "true"/"false"/"1"/"0", numbers, enum names. */
HUSH_API hush_status hush_filter_set_string(hush_filter filter, const char *name, const char *value);
HUSH_API hush_status hush_filter_get_bool(hush_filter filter, const char *name, int *value);
HUSH_API hush_status hush_filter_get_int(hush_filter filter, const char *name, int *value);
HUSH_API hush_status hush_filter_get_float(hush_filter filter, const char *name, float *value);

/*
 * Binds a named image (one of the class's images) to caller-owned memory.
 * Only the view is stored: the memory must stay valid, and is read or
 * written, during each hush_filter_execute(). Rebinding replaces the view;
 * a view of a new size needs hush_filter_commit() again.
 * Input images may be FLOAT* or HALF*, with at least the class's channel
 * count (extra channels are ignored); outputs must have exactly that many.
 * HALF outputs get finite values beyond the half range as +-65504 (the
 * largest half), not Inf, as hush_frame_write_exr does.
 */
HUSH_API hush_status hush_filter_set_image(hush_filter filter, const char *name,
                                           const hush_image_view *view);
HUSH_API hush_status hush_filter_unset_image(hush_filter filter, const char *name);

/*
 * Checks bindings (required images bound, equal sizes, valid formats and
 * strides) and allocates the filter's buffers and history. Commit after the
 * first bindings and after any size change; a commit that changes the size
 * resets the history.
 */
HUSH_API hush_status hush_filter_commit(hush_filter filter);

typedef enum hush_motion_source {
  /* Back-project "position" (or, without it, the point reconstructed from
   * "depth" and this frame's matrices and jitter) with the previous frame's
   * matrices. Exact for static scenes. */
  HUSH_MOTION_CAMERA = 0,
  /* Use the "motion" image (previous minus current, pixels). Needed for
   * moving objects. */
  HUSH_MOTION_VECTORS = 1
} hush_motion_source;

typedef enum hush_history_mode {
  HUSH_HISTORY_CONTINUE = 0, /* reuse history where it is consistent */
  HUSH_HISTORY_RESET = 1     /* camera cut: forget all history */
} hush_history_mode;

/*
 * What a filter needs to know about one frame besides its images.
 * Initialise with hush_frame_info_init(), which sets size, identity
 * matrices, zero jitter, CAMERA motion and CONTINUE; then fill in. The size
 * field lets the struct grow: the library reads only what the caller's
 * version of the struct holds.
 */
typedef struct hush_frame_info {
  size_t size;                  /* sizeof(hush_frame_info) */
  uint64_t frame_index;
  float world_to_view[16];      /* this frame, column-major */
  float view_to_clip[16];
  float prev_world_to_view[16]; /* previous frame */
  float prev_view_to_clip[16];
  float jitter[2];              /* pixels, this frame */
  float prev_jitter[2];
  hush_motion_source motion;
  hush_history_mode history;
} hush_frame_info;

HUSH_API void hush_frame_info_init(hush_frame_info *info);

/*
 * Runs the filter on one frame: reads the bound inputs, updates the history
 * and writes the bound outputs. Deterministic: the same inputs and history
 * give bit-identical outputs, whatever the thread count. The first frame after commit
 * (or a RESET) starts with no history.
 */
HUSH_API hush_status hush_filter_execute(hush_filter filter, const hush_frame_info *info);

/* Wall-clock time of each stage of the last execute, in milliseconds.
 * *names and *ms point into the filter and stay valid until its next
 * execute or release. */
HUSH_API hush_status hush_filter_get_timings(hush_filter filter, const char *const **names,
                                             const double **ms, uint32_t *count);

/* ------------------------------------------------------------------------ */
/* Frames: named multi-channel images in memory, and their files            */
/* ------------------------------------------------------------------------ */

/*
 * A hush_frame holds named layers ("color", "albedo", "normal", "position",
 * "depth", "motion", "id", "ref", "spp", "variance", ...), each an
 * interleaved float32 image of 1 to 4 channels, all of one size. The
 * library owns the pixels; hush_frame_get_layer() gives a view of them.
 * docs/sequence-format.md lists the EXR channel names of each layer.
 */
typedef struct hush_frame_t *hush_frame;

/* A new frame with no layers. The caller owns the returned reference. */
HUSH_API hush_frame hush_frame_new(hush_device device, uint32_t width, uint32_t height);
HUSH_API void hush_frame_retain(hush_frame frame);
HUSH_API void hush_frame_release(hush_frame frame);
HUSH_API uint32_t hush_frame_width(hush_frame frame);
HUSH_API uint32_t hush_frame_height(hush_frame frame);

/* Adds (or replaces) a zero-filled layer of 1..4 float channels and returns
 * a view of it in *view (may be NULL). */
HUSH_API hush_status hush_frame_add_layer(hush_frame frame, const char *name, int channels,
                                          hush_image_view *view);
/* A view of an existing layer; HUSH_ERROR_NOT_FOUND if the frame lacks it.
 * view may be NULL to test whether the layer exists. */
HUSH_API hush_status hush_frame_get_layer(hush_frame frame, const char *name, hush_image_view *view);
HUSH_API uint32_t hush_frame_layer_count(hush_frame frame);
/* Name of layer i, or NULL; owned by the frame. */
HUSH_API const char *hush_frame_layer_name(hush_frame frame, uint32_t index);

/*
 * Reads a frame from an EXR file (half or float, scanline or tiled, any
 * compression OpenEXR supports). Channels are grouped into layers by the
 * names in docs/sequence-format.md; unknown channels are kept as 1-channel
 * layers of their own name. NaN/Inf pixels are kept: filters report them.
 * The caller owns *frame.
 */
HUSH_API hush_status hush_frame_read_exr(hush_device device, const char *path, hush_frame *frame);

typedef enum hush_exr_type {
  HUSH_EXR_HALF = 0,
  HUSH_EXR_FLOAT = 1
} hush_exr_type;

/* Writes every layer to one EXR (ZIP compression) through a temporary file
 * renamed into place, so a failure never leaves a partial file. With
 * HUSH_EXR_HALF the "id", "depth", "position" and "vis" layers are still
 * written as float: ids and the visibility buffer's triangle indices must
 * stay exact and half is too coarse for geometry and barycentrics. Finite
 * values beyond the half range are written as +-65504 (the largest half),
 * not Inf; NaN and Inf are kept. */
HUSH_API hush_status hush_frame_write_exr(hush_frame frame, const char *path, hush_exr_type type);

/* Display transform for pictures: radiance * 2^exposure, then tone mapping,
 * then sRGB encoding, 8 bits. */
typedef enum hush_tonemap {
  HUSH_TONEMAP_CLAMP = 0,    /* clip to [0, 1] */
  HUSH_TONEMAP_REINHARD = 1, /* x / (1 + x) per channel */
  HUSH_TONEMAP_ACES = 2      /* Narkowicz's fit of the ACES filmic curve */
} hush_tonemap;

/* Writes one 1- or 3-channel (or the first 3 of 4) view as an 8-bit sRGB
 * PNG, through a temporary file. NaN/Inf pixels are an error. */
HUSH_API hush_status hush_image_write_png(hush_device device, const hush_image_view *view,
                                          const char *path, float exposure, hush_tonemap tonemap);

/* Reads a PNG (8 or 16 bits, gray, palette or RGB, alpha dropped) into a new
 * frame with one layer named layer_name, decoded from sRGB to linear. */
HUSH_API hush_status hush_frame_read_png(hush_device device, const char *path,
                                         const char *layer_name, hush_frame *frame);

/* PFM (Portable Float Map), 1 or 3 channels, for exchange with other tools. */
HUSH_API hush_status hush_image_write_pfm(hush_device device, const hush_image_view *view,
                                          const char *path);
/* Reads a PFM into a new frame with one layer named layer_name. */
HUSH_API hush_status hush_frame_read_pfm(hush_device device, const char *path,
                                         const char *layer_name, hush_frame *frame);

/* ------------------------------------------------------------------------ */
/* nca filter: learned weights (docs/nca.md)                                */
/* ------------------------------------------------------------------------ */

/*
 * Loads a weights file written by `hush train-nca` (versioned format with a
 * checksum, docs/nca.md) into a filter of class "nca"; it replaces the
 * built-in weights from the next execute and survives commits. path NULL
 * returns to the built-in weights. HUSH_ERROR_IO, HUSH_ERROR_CORRUPT or
 * HUSH_ERROR_UNSUPPORTED with a message when the file is refused (the
 * filter keeps its previous weights); HUSH_ERROR_INVALID_ARGUMENT when the
 * filter is not an "nca" filter.
 */
HUSH_API hush_status hush_nca_load_weights(hush_filter filter, const char *path);

/* ------------------------------------------------------------------------ */
/* end of the nca section                                                   */
/* ------------------------------------------------------------------------ */

/* ======================================================================== */
/* Hashed path-space filtering (hashed-path-space-filtering-binder-2019.md) */
/* ======================================================================== */
/*
 * A filter that lives inside a path tracer: each path hands one selected
 * vertex (e.g. its first sufficiently diffuse hit) to a hash table keyed by
 * the vertex's jittered, quantised world position (level of detail from the
 * distance along the path, Algorithm 1); vertices with the same key average
 * their radiance, and the path then uses its cell's average instead of its
 * own estimate. Cell averages persist across frames (a sample-count
 * weighted exponential average, §3.3) and stale cells are evicted by age
 * (§3.4). docs/psf.md describes it; docs/api.md shows the calls.
 *
 * Per frame:  hush_psf_begin_frame -> hush_psf_add_vertices (any threads,
 * concurrently) -> hush_psf_resolve -> hush_psf_lookup (any threads).
 * Unlike the rest of the API, hush_psf_add_vertices and hush_psf_lookup may
 * be called from many threads at once on one object (between begin_frame and
 * resolve, and after resolve, respectively); everything else is
 * one-thread-at-a-time as usual.
 */
typedef struct hush_psf_t *hush_psf;

/* A ticket of hush_psf_add_vertices for a vertex that found no cell (the
 * cache line was full of cells of this frame, or the vertex was not finite):
 * hush_psf_lookup returns the vertex's own radiance for it. */
#define HUSH_PSF_NO_CELL 0xffffffffu

/* hush_psf_vertex.flags: the surface is glossy; its direction goes into
 * the verification hash (cells then differ by the direction of view), and
 * its cells are "glossy_scale" times larger. */
#define HUSH_PSF_GLOSSY 1u

typedef struct hush_psf_vertex {
  float position[3];       /* world space */
  float normal[3];         /* unit shading normal */
  float origin[3];         /* the previous vertex of the path (the camera for a first hit) */
  float distance;          /* path length from the camera to origin (0 for a first hit) */
  float radiance[3];       /* what is averaged: e.g. the path's radiance leaving the vertex
                            * towards origin, divided by the vertex's albedo */
  uint32_t seed;           /* random seed of the tangent-plane jitter: unique per path,
                            * e.g. (pixel * spp + sample); the frame index is mixed in */
  uint32_t flags;          /* HUSH_PSF_GLOSSY */
} hush_psf_vertex;

/* Statistics of the last resolved frame (the paper's Figure 7 and more). */
typedef struct hush_psf_stats {
  uint64_t vertices;       /* added this frame */
  uint64_t collisions;     /* vertices whose cell was not at the first slot probed */
  uint64_t failed;         /* vertices that found no cell (HUSH_PSF_NO_CELL) */
  uint64_t cells_used;     /* distinct cells that received vertices this frame */
  uint64_t cells_occupied; /* cells holding a key after resolve (history included) */
  uint64_t evictions;      /* cells replaced while adding + cells aged out at resolve */
  uint64_t table_size;     /* slots */
  double occupancy;        /* cells_occupied / table_size */
  double ms_resolve;       /* wall time of hush_psf_resolve */
} hush_psf_stats;

/*
 * A filter for frames of width x height pixels: the table holds
 * table_size * width * height slots (parameter "table_size", default 1),
 * rounded up to whole 64-byte cache lines of 16 slots. The caller owns the
 * returned reference. NULL and an error on the device on failure.
 */
HUSH_API hush_psf hush_psf_new(hush_device device, uint32_t width, uint32_t height);
HUSH_API void hush_psf_retain(hush_psf psf);
HUSH_API void hush_psf_release(hush_psf psf);

/* The parameter table (static): "scale", "glossy_scale", "table_size",
 * "jitter", "normals", "glossy_normals", "probes", "max_samples", "max_age",
 * "temporal"; docs/psf.md explains them. */
HUSH_API const hush_param_info *hush_psf_params(uint32_t *count);
/* Setters validate name, type and range as hush_filter_set_*. A change of
 * "table_size" reallocates the table at the next begin_frame (history lost). */
HUSH_API hush_status hush_psf_set_float(hush_psf psf, const char *name, float value);
HUSH_API hush_status hush_psf_set_int(hush_psf psf, const char *name, int value);
HUSH_API hush_status hush_psf_set_string(hush_psf psf, const char *name, const char *value);
HUSH_API hush_status hush_psf_get_float(hush_psf psf, const char *name, float *value);

/*
 * Starts a frame. pixel_angle: the width of one pixel on a plane at unit
 * distance from the camera (2 tan(fov_y / 2) / height), which sets the cell
 * size: scale * pixel_angle * 2^floor(log2(distance)). HUSH_HISTORY_RESET
 * empties the table (a camera cut, or a changed scene). Resolve each frame
 * before the next begin_frame: otherwise the cells average both frames'
 * vertices together.
 */
HUSH_API hush_status hush_psf_begin_frame(hush_psf psf, uint64_t frame_index, float pixel_angle,
                                          hush_history_mode history);

/*
 * Adds count vertices to their cells and writes each one's ticket (a slot,
 * or HUSH_PSF_NO_CELL) to tickets[i]. Thread-safe: call it from the path
 * tracer's threads concurrently (accumulation uses atomics). Each call
 * sums the vertices of its recently seen cells locally first, so pass many
 * vertices per call, in screen order when possible. Reports no errors through the
 * device (it may run on many threads); returns INVALID_ARGUMENT or
 * INVALID_OPERATION (no begin_frame) without recording them.
 */
HUSH_API hush_status hush_psf_add_vertices(hush_psf psf, const hush_psf_vertex *vertices,
                                           uint32_t count, uint32_t *tickets);

/* Averages the frame's cells, blends them with their history, ages and
 * evicts stale cells, and fills the statistics. Uses the device's threads. */
HUSH_API hush_status hush_psf_resolve(hush_psf psf);

/*
 * After resolve: the filtered radiance of count vertices, from their tickets,
 * into rgb (3 floats each); a vertex with HUSH_PSF_NO_CELL gets its own
 * radiance. The path's filtered contribution is its throughput up to the
 * vertex times this. Thread-safe.
 */
HUSH_API hush_status hush_psf_lookup(hush_psf psf, const hush_psf_vertex *vertices,
                                     const uint32_t *tickets, uint32_t count, float *rgb);

HUSH_API hush_status hush_psf_get_stats(hush_psf psf, hush_psf_stats *stats);

/* ======================================================================== */
/* End of hashed path-space filtering                                       */
/* ======================================================================== */

#ifdef __cplusplus
}
#endif

#endif /* HUSH_H */
