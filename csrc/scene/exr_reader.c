/* OpenEXR files through OpenEXRCore (and OpenEXR's C++ library, loaded at run time, for the
 * compressions OpenEXRCore lacks).  Returns linear RGB pixels, row 0 the top. */
#define _POSIX_C_SOURCE 200809L /* pread */

#include "scene/image_readers.h"

#include <errno.h>
#include <stdio.h>
#include <string.h>
#include <dlfcn.h>
#include <unistd.h>

#include <ImfCRgbaFile.h>
#include <OpenEXRConfig.h>
#include <openexr.h>

/* A data window of w x h pixels that the environment can hold. */
static wenv_status check_data_window(int64_t w, int64_t h, const char *path, wenv_error *err)
{
    if (w <= 0 || h <= 0 || (uint64_t)w > WENV_IMAGE_MAX_SIDE || (uint64_t)h > WENV_IMAGE_MAX_SIDE ||
        (uint64_t)w * (uint64_t)h > WENV_IMAGE_MAX_PIXELS)
        return wenv_error_set(err, WENV_ERR_IO, "cannot read OpenEXR file '%s': unusable data window %lld x %lld",
                              path, (long long)w, (long long)h);
    return WENV_OK;
}

typedef struct {
    int fd;
    int64_t size;
    char message[200]; /* first detailed message from OpenEXRCore */
} exr_stream;

static int64_t exr_read_cb(exr_const_context_t ctxt, void *user, void *buffer, uint64_t sz, uint64_t offset,
                           exr_stream_error_func_ptr_t error_cb)
{
    exr_stream *s = user;
    uint8_t *dst = buffer;
    uint64_t done = 0;
    if (offset > (uint64_t)s->size)
        return 0; /* past the end: OpenEXRCore reports the short read */
    while (done < sz) {
        size_t want = sz - done > ((size_t)1 << 30) ? ((size_t)1 << 30) : (size_t)(sz - done);
        ssize_t got = pread(s->fd, dst + done, want, (off_t)(offset + done));
        if (got < 0) {
            if (errno == EINTR)
                continue;
            if (error_cb)
                error_cb(ctxt, EXR_ERR_READ_IO, "read error at offset %llu", (unsigned long long)(offset + done));
            return -1;
        }
        if (got == 0)
            break;
        done += (uint64_t)got;
    }
    return (int64_t)done;
}

static int64_t exr_size_cb(exr_const_context_t ctxt, void *user)
{
    (void)ctxt;
    return ((exr_stream *)user)->size;
}

static void exr_error_cb(exr_const_context_t ctxt, exr_result_t code, const char *msg)
{
    void *user = NULL;
    /* silence OpenEXRCore's default printing to stderr; keep the first message for the exception */
    if (ctxt && exr_get_user_data(ctxt, &user) == EXR_ERR_SUCCESS && user) {
        exr_stream *s = user;
        if (!s->message[0])
            snprintf(s->message, sizeof s->message, "%s", msg ? msg : exr_get_error_code_as_string(code));
    }
}

static wenv_status exr_fail(wenv_error *err, const char *path, const exr_stream *s, exr_result_t rv)
{
    return wenv_error_set(err, WENV_ERR_IO, "cannot read OpenEXR file '%s': %s", path,
                          s->message[0] ? s->message : exr_get_error_code_as_string(rv));
}

/* Colour slot of an EXR channel: 0..2 for R, G, B; 3 for Y (grey); -1 otherwise. */
static int exr_channel_slot(const char *name)
{
    if (!name)
        return -1;
    if (strcmp(name, "R") == 0)
        return 0;
    if (strcmp(name, "G") == 0)
        return 1;
    if (strcmp(name, "B") == 0)
        return 2;
    if (strcmp(name, "Y") == 0)
        return 3;
    return -1;
}

/* Room for one chunk's values of one channel, grown as chunks need. */
typedef struct {
    float *values;
    size_t room;
} exr_scratch;

/* Whether a chunk whose top-left pixel is (x_off, y_off) in the data window lies inside it. */
static int chunk_inside(const exr_chunk_info_t *cinfo, size_t width, size_t height, int64_t x_off, int64_t y_off)
{
    return x_off >= 0 && y_off >= 0 && cinfo->width > 0 && cinfo->height > 0 &&
           (uint64_t)x_off + (uint64_t)cinfo->width <= width && (uint64_t)y_off + (uint64_t)cinfo->height <= height;
}

/* Decodes one chunk whose top-left pixel is (x_off, y_off) in the data window into rgb.  Channels
 * not wanted are decoded into `scratch` and dropped: OpenEXRCore 3.1 picks unpacking routines for
 * 3 or 4 half channels that write every channel, a skipped one (decode_to_ptr NULL) included --
 * a grey file with two of R, G, B beside Y crashed it. */
static exr_result_t exr_decode_chunk(exr_context_t ctx, const exr_chunk_info_t *cinfo, exr_decode_pipeline_t *dec,
                                     int *initialised, float *rgb, size_t width, int64_t x_off, int64_t y_off,
                                     int grey, exr_scratch *scratch)
{
    size_t chunk_pixels = (size_t)cinfo->width * (size_t)cinfo->height;
    if (scratch->room < chunk_pixels) {
        float *grown = realloc(scratch->values, chunk_pixels * sizeof(float));
        if (!grown)
            return EXR_ERR_OUT_OF_MEMORY;
        scratch->values = grown;
        scratch->room = chunk_pixels;
    }
    exr_result_t rv = *initialised ? exr_decoding_update(ctx, 0, cinfo, dec)
                                   : exr_decoding_initialize(ctx, 0, cinfo, dec);
    if (rv != EXR_ERR_SUCCESS)
        return rv;
    *initialised = 1;
    for (int16_t c = 0; c < dec->channel_count; c++) {
        exr_coding_channel_info_t *ch = &dec->channels[c];
        int slot = exr_channel_slot(ch->channel_name);
        ch->user_bytes_per_element = 4;
        ch->user_data_type = EXR_PIXEL_FLOAT;
        if (grey ? slot != 3 : (slot < 0 || slot > 2)) { /* not wanted */
            ch->decode_to_ptr = (uint8_t *)scratch->values;
            ch->user_pixel_stride = (int32_t)sizeof(float);
            ch->user_line_stride = (int32_t)(sizeof(float) * (size_t)cinfo->width);
            continue;
        }
        ch->decode_to_ptr = (uint8_t *)(rgb + ((size_t)y_off * width + (size_t)x_off) * 3 + (grey ? 0 : slot));
        ch->user_pixel_stride = 3 * (int32_t)sizeof(float);
        ch->user_line_stride = (int32_t)(3 * sizeof(float) * width);
    }
    rv = exr_decoding_choose_default_routines(ctx, 0, dec);
    if (rv != EXR_ERR_SUCCESS)
        return rv;
    return exr_decoding_run(ctx, 0, dec);
}

/* The decoding state kept from chunk to chunk. */
typedef struct {
    exr_decode_pipeline_t pipeline;
    int initialised;
    exr_scratch scratch;
} exr_decoder;

/* The image as it is decoded: its first `rows` rows held (zeroed until decoded), grown as chunks
 * further down arrive, so that memory follows what the file holds rather than what its header
 * claims (a huge window over a few compressed bytes fails at its first chunk, not at an allocation
 * of its size). */
typedef struct {
    float *rgb;
    size_t rows, width, height;
} exr_image;

static int image_cover(exr_image *img, size_t rows)
{
    if (rows <= img->rows)
        return 0;
    size_t room = img->rows * 2 > rows ? img->rows * 2 : rows;
    room = room < img->height ? room : img->height;
    size_t row_floats = img->width * 3;
    float *grown = realloc(img->rgb, room * row_floats * sizeof *grown);
    if (!grown)
        return -1;
    memset(grown + img->rows * row_floats, 0, (room - img->rows) * row_floats * sizeof *grown);
    img->rgb = grown;
    img->rows = room;
    return 0;
}

/* One chunk whose top-left pixel is (x_off, y_off) in the data window: checked to lie inside it and
 * to hold as many bytes as its pixels can come from, then with img decoded into it. */
static exr_result_t exr_visit_chunk(exr_context_t ctx, const exr_chunk_info_t *cinfo, int64_t x_off, int64_t y_off,
                                    exr_image *img, size_t width, size_t height, int grey, exr_decoder *d,
                                    exr_stream *stream)
{
    if (!chunk_inside(cinfo, width, height, x_off, y_off))
        return EXR_ERR_BAD_CHUNK_LEADER; /* a chunk outside the data window: corrupt file */
    /* Writers store a chunk that would not shrink as it is, so a chunk never holds more bytes than
     * its pixels, and an uncompressed one exactly as many: OpenEXRCore 3.1 decodes a short
     * uncompressed chunk to nothing and reports success. */
    if (cinfo->packed_size == 0 || cinfo->packed_size > cinfo->unpacked_size ||
        (cinfo->compression == EXR_COMPRESSION_NONE && cinfo->packed_size != cinfo->unpacked_size)) {
        if (!stream->message[0])
            snprintf(stream->message, sizeof stream->message,
                     "the chunk at pixel (%lld, %lld) holds %llu bytes for %llu bytes of pixels", (long long)x_off,
                     (long long)y_off, (unsigned long long)cinfo->packed_size,
                     (unsigned long long)cinfo->unpacked_size);
        return EXR_ERR_CORRUPT_CHUNK;
    }
    if (!img)
        return EXR_ERR_SUCCESS;
    if (image_cover(img, (size_t)y_off + (size_t)cinfo->height) < 0)
        return EXR_ERR_OUT_OF_MEMORY;
    return exr_decode_chunk(ctx, cinfo, &d->pipeline, &d->initialised, img->rgb, width, x_off, y_off, grey,
                            &d->scratch);
}

/* Visits every chunk of the data window (width x height, part 0, level 0 if tiled) in order of rows:
 * with img, decoding each into it; with img NULL only checking that each is in the file (its table
 * entry and leader readable, its sizes possible). */
static exr_result_t exr_walk_chunks(exr_context_t ctx, exr_storage_t storage, const exr_attr_box2i_t *dw,
                                    size_t width, size_t height, exr_image *img, int grey, exr_decoder *d,
                                    exr_stream *stream)
{
    exr_chunk_info_t cinfo;
    exr_result_t rv;
    if (storage == EXR_STORAGE_SCANLINE) {
        int32_t lines = 0;
        if ((rv = exr_get_scanlines_per_chunk(ctx, 0, &lines)) != EXR_ERR_SUCCESS)
            return rv;
        if (lines <= 0)
            return EXR_ERR_INVALID_ATTR;
        for (int64_t y = dw->min.y; y <= dw->max.y; y += lines) {
            if ((rv = exr_read_scanline_chunk_info(ctx, 0, (int)y, &cinfo)) != EXR_ERR_SUCCESS ||
                (rv = exr_visit_chunk(ctx, &cinfo, (int64_t)cinfo.start_x - dw->min.x,
                                      (int64_t)cinfo.start_y - dw->min.y, img, width, height, grey, d, stream)) !=
                    EXR_ERR_SUCCESS)
                return rv;
        }
        return EXR_ERR_SUCCESS;
    }
    int32_t tw = 0, th = 0;
    if ((rv = exr_get_tile_sizes(ctx, 0, 0, 0, &tw, &th)) != EXR_ERR_SUCCESS)
        return rv;
    if (tw <= 0 || th <= 0)
        return EXR_ERR_INVALID_ATTR;
    size_t ntx = (width + (size_t)tw - 1) / (size_t)tw, nty = (height + (size_t)th - 1) / (size_t)th;
    for (size_t ty = 0; ty < nty; ty++) {
        for (size_t tx = 0; tx < ntx; tx++) {
            /* tile positions count from the data window's corner */
            if ((rv = exr_read_tile_chunk_info(ctx, 0, (int)tx, (int)ty, 0, 0, &cinfo)) != EXR_ERR_SUCCESS ||
                (rv = exr_visit_chunk(ctx, &cinfo, (int64_t)(tx * (size_t)tw), (int64_t)(ty * (size_t)th), img,
                                      width, height, grey, d, stream)) != EXR_ERR_SUCCESS)
                return rv;
        }
    }
    return EXR_ERR_SUCCESS;
}

/* OpenEXRCore 3.1 cannot decompress DWAA/DWAB ("not yet implemented in C"), and Blender's bundled
 * HDRIs are DWAB.  For those files only, wenv falls back to OpenEXR's own C interface to its C++
 * library (ImfCRgbaFile.h, shipped in the same Debian package as OpenEXRCore).  It is loaded with
 * dlopen on demand so the build keeps linking OpenEXRCore alone; the handle is never closed, as a
 * linked library would never be unloaded either. */
typedef struct {
    ImfInputFile *(*open)(const char name[]);
    int (*close)(ImfInputFile *in);
    int (*set_frame_buffer)(ImfInputFile *in, ImfRgba *base, size_t x_stride, size_t y_stride);
    int (*read_pixels)(ImfInputFile *in, int scan_line1, int scan_line2);
    const ImfHeader *(*header)(const ImfInputFile *in);
    int (*channels)(const ImfInputFile *in);
    void (*data_window)(const ImfHeader *hdr, int *x_min, int *y_min, int *x_max, int *y_max);
    void (*half_to_float)(int n, const ImfHalf h[], float f[]);
    const char *(*error_message)(void);
} imf_api;

#define STR_(x) #x
#define STR(x) STR_(x)

static int imf_api_load(imf_api *api, char *why, size_t why_size)
{
    /* the soname of the C++ library that ships with the OpenEXRCore we were built against */
    char soname[64];
    const char *lib_version = OPENEXR_LIB_VERSION_STRING;
    size_t major_len = strcspn(lib_version, ".");
    snprintf(soname, sizeof soname, "libOpenEXR-%d_%d.so.%.*s", OPENEXR_VERSION_MAJOR, OPENEXR_VERSION_MINOR,
             (int)major_len, lib_version);
    const char *candidates[] = {soname, "libOpenEXR-" STR(OPENEXR_VERSION_MAJOR) "_" STR(OPENEXR_VERSION_MINOR) ".so",
                                "libOpenEXR.so"};
    void *lib = NULL;
    for (size_t i = 0; i < sizeof candidates / sizeof *candidates && !lib; i++)
        lib = dlopen(candidates[i], RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        const char *e = dlerror();
        snprintf(why, why_size, "%s", e ? e : soname);
        return -1;
    }
    struct {
        void **slot;
        const char *name;
    } symbols[] = {
        {(void **)&api->open, "ImfOpenInputFile"},
        {(void **)&api->close, "ImfCloseInputFile"},
        {(void **)&api->set_frame_buffer, "ImfInputSetFrameBuffer"},
        {(void **)&api->read_pixels, "ImfInputReadPixels"},
        {(void **)&api->header, "ImfInputHeader"},
        {(void **)&api->channels, "ImfInputChannels"},
        {(void **)&api->data_window, "ImfHeaderDataWindow"},
        {(void **)&api->half_to_float, "ImfHalfToFloatArray"},
        {(void **)&api->error_message, "ImfErrorMessage"},
    };
    for (size_t i = 0; i < sizeof symbols / sizeof *symbols; i++) {
        /* POSIX's way to store a function address obtained from dlsym */
        *symbols[i].slot = dlsym(lib, symbols[i].name);
        if (!*symbols[i].slot) {
            snprintf(why, why_size, "symbol %s missing from %s", symbols[i].name, soname);
            return -1;
        }
    }
    return 0;
}

static wenv_status load_exr_rgba(const char *path, float **out, size_t *out_h, size_t *out_w, wenv_error *err)
{
    imf_api api;
    char why[256];
    if (imf_api_load(&api, why, sizeof why) < 0)
        return wenv_error_set(err, WENV_ERR_IO,
                              "cannot read OpenEXR file '%s': its compression (DWAA/DWAB) needs OpenEXR's library "
                              "libOpenEXR, which could not be loaded (%s)",
                              path, why);
    ImfInputFile *in = api.open(path);
    if (!in) {
        const char *m = api.error_message();
        return wenv_error_set(err, WENV_ERR_IO, "cannot read OpenEXR file '%s': %s", path, m ? m : "unknown error");
    }
    exr_image image = {NULL, 0, 0, 0};
    float *row_f = NULL;
    ImfRgba *buf = NULL;
    int x_min, y_min, x_max, y_max;
    api.data_window(api.header(in), &x_min, &y_min, &x_max, &y_max);
    int64_t w64 = (int64_t)x_max - x_min + 1, h64 = (int64_t)y_max - y_min + 1;
    if (!(api.channels(in) & (IMF_WRITE_RGB | IMF_WRITE_Y))) {
        wenv_error_set(err, WENV_ERR_IO, "cannot read OpenEXR file '%s': it has no R, G, B (or Y) channels", path);
        goto done;
    }
    if (check_data_window(w64, h64, path, err))
        goto done;
    size_t width = (size_t)w64, height = (size_t)h64;
    image.width = width;
    image.height = height;
    /* bands of 256 rows (a DWAB chunk), fewer where a band would pass 16 MB, the image grown as they
     * arrive (exr_image) */
    size_t band = ((size_t)16 << 20) / (width * sizeof *buf);
    band = band < 1 ? 1 : band > 256 ? 256 : band;
    buf = malloc(width * band * sizeof *buf);
    row_f = malloc(width * 4 * sizeof *row_f);
    if (!buf || !row_f) {
        wenv_error_set(err, WENV_ERR_NOMEM, "out of memory reading '%s' (%zu x %zu)", path, width, height);
        goto done;
    }
    for (size_t r0 = 0; r0 < height; r0 += band) {
        size_t rows = height - r0 < band ? height - r0 : band;
        int64_t y0 = (int64_t)y_min + (int64_t)r0;
        /* the RGBA interface addresses pixels by absolute (x, y): shift the base by the band's corner */
        uintptr_t base = (uintptr_t)buf - ((uintptr_t)(intptr_t)x_min + (uintptr_t)(intptr_t)y0 * width) * sizeof *buf;
        if (!api.set_frame_buffer(in, (ImfRgba *)base, 1, width) ||
            !api.read_pixels(in, (int)y0, (int)(y0 + (int64_t)rows - 1))) {
            const char *m = api.error_message();
            wenv_error_set(err, WENV_ERR_IO, "cannot read OpenEXR file '%s': %s", path, m ? m : "unknown error");
            goto done;
        }
        if (image_cover(&image, r0 + rows) < 0) {
            wenv_error_set(err, WENV_ERR_NOMEM, "out of memory reading '%s' (%zu x %zu)", path, width, height);
            goto done;
        }
        for (size_t r = 0; r < rows; r++) {
            api.half_to_float((int)(4 * width), &buf[r * width].r, row_f);
            float *dst = image.rgb + (r0 + r) * width * 3;
            for (size_t x = 0; x < width; x++)
                for (size_t c = 0; c < 3; c++)
                    dst[x * 3 + c] = row_f[4 * x + c];
        }
    }
    *out = image.rgb;
    *out_h = height;
    *out_w = width;
    image.rgb = NULL;
done:
    api.close(in);
    free(buf);
    free(image.rgb);
    free(row_f);
    return err->status;
}

/* Whether reading stops at a chunk: on an error (set), or where OpenEXRCore lacks the compression
 * (*use_rgba set: OpenEXR's C++ library reads the file instead). */
static int chunk_failed(exr_result_t rv, int *use_rgba, const char *path, const exr_stream *stream, wenv_error *err)
{
    if (rv == EXR_ERR_FEATURE_NOT_IMPLEMENTED) {
        *use_rgba = 1;
        return 1;
    }
    if (rv != EXR_ERR_SUCCESS) {
        exr_fail(err, path, stream, rv);
        return 1;
    }
    return 0;
}

wenv_status wenv_read_exr(int fd, int64_t size, const char *path, float **out, size_t *out_h, size_t *out_w,
                            wenv_error *err)
{
    exr_stream stream = {fd, size, ""};
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.error_handler_fn = exr_error_cb;
    init.user_data = &stream;
    init.read_fn = exr_read_cb;
    init.size_fn = exr_size_cb;
    exr_context_t ctx = NULL;
    exr_result_t rv = exr_start_read(&ctx, path, &init);
    if (rv != EXR_ERR_SUCCESS) {
        exr_fail(err, path, &stream, rv);
        exr_finish(&ctx);
        return err->status;
    }
    /* OpenEXRCore reports a header fault it can step over (an attribute of impossible size, say)
     * and goes on; OpenEXR's C++ library parses such a header its own way, and 3.1 allocates what
     * a corrupt attribute's size claims (gigabytes for a file of a few hundred bytes), so it is
     * handed only files whose header parsed cleanly */
    int header_clean = !stream.message[0];
    exr_image image = {NULL, 0, 0, 0};
    exr_decoder decoder = {EXR_DECODE_PIPELINE_INITIALIZER, 0, {NULL, 0}};
    int use_rgba = 0;
    exr_storage_t storage;
    exr_attr_box2i_t dw;
    const exr_attr_chlist_t *chl = NULL;
    if ((rv = exr_get_storage(ctx, 0, &storage)) != EXR_ERR_SUCCESS ||
        (rv = exr_get_data_window(ctx, 0, &dw)) != EXR_ERR_SUCCESS ||
        (rv = exr_get_channels(ctx, 0, &chl)) != EXR_ERR_SUCCESS || !chl) {
        exr_fail(err, path, &stream, rv);
        goto done;
    }
    if (storage != EXR_STORAGE_SCANLINE && storage != EXR_STORAGE_TILED) {
        wenv_error_set(err, WENV_ERR_IO, "cannot read OpenEXR file '%s': deep images are not supported", path);
        goto done;
    }
    int64_t w64 = (int64_t)dw.max.x - dw.min.x + 1, h64 = (int64_t)dw.max.y - dw.min.y + 1;
    if (check_data_window(w64, h64, path, err))
        goto done;
    size_t width = (size_t)w64, height = (size_t)h64;
    int have[4] = {0, 0, 0, 0};
    for (int i = 0; i < chl->num_channels; i++) {
        const exr_attr_chlist_entry_t *e = &chl->entries[i];
        int slot = exr_channel_slot(e->name.str);
        if (slot < 0)
            continue;
        if (e->pixel_type != EXR_PIXEL_HALF && e->pixel_type != EXR_PIXEL_FLOAT) {
            wenv_error_set(err, WENV_ERR_IO, "cannot read OpenEXR file '%s': channel %s is not half or float", path,
                           e->name.str);
            goto done;
        }
        if (e->x_sampling != 1 || e->y_sampling != 1) {
            wenv_error_set(err, WENV_ERR_IO, "cannot read OpenEXR file '%s': channel %s is subsampled", path,
                           e->name.str);
            goto done;
        }
        have[slot] = 1;
    }
    int grey = !(have[0] && have[1] && have[2]);
    if (grey && !have[3]) {
        char names[160] = "";
        size_t len = 0;
        for (int i = 0; i < chl->num_channels && len + 1 < sizeof names; i++)
            len += (size_t)snprintf(names + len, sizeof names - len, "%s%s", i ? ", " : "",
                                    chl->entries[i].name.str ? chl->entries[i].name.str : "?");
        wenv_error_set(err, WENV_ERR_IO,
                       "cannot read OpenEXR file '%s': it needs R, G and B (or Y) channels, found: %s", path,
                       names[0] ? names : "none");
        goto done;
    }
    /* every chunk the data window needs must be in the file, its sizes possible, before any is
     * decoded (or the file handed to OpenEXR's C++ library) */
    rv = exr_walk_chunks(ctx, storage, &dw, width, height, NULL, grey, &decoder, &stream);
    if (chunk_failed(rv, &use_rgba, path, &stream, err))
        goto done;
    image.width = width;
    image.height = height;
    rv = exr_walk_chunks(ctx, storage, &dw, width, height, &image, grey, &decoder, &stream);
    if (rv == EXR_ERR_OUT_OF_MEMORY) {
        wenv_error_set(err, WENV_ERR_NOMEM, "out of memory reading '%s' (%zu x %zu)", path, width, height);
        goto done;
    }
    if (chunk_failed(rv, &use_rgba, path, &stream, err))
        goto done;
    if (image.rows != height) { /* every row is some chunk's: the walk covered them all */
        wenv_error_set(err, WENV_ERR_IO, "cannot read OpenEXR file '%s': rows past %zu have no chunk", path,
                       image.rows);
        goto done;
    }
    if (grey)
        for (size_t i = 0; i < width * height; i++)
            image.rgb[3 * i + 1] = image.rgb[3 * i + 2] = image.rgb[3 * i];
    *out = image.rgb;
    *out_h = height;
    *out_w = width;
    image.rgb = NULL;
done:
    if (decoder.initialised)
        exr_decoding_destroy(ctx, &decoder.pipeline);
    exr_finish(&ctx);
    free(image.rgb);
    free(decoder.scratch.values);
    if (use_rgba && !header_clean)
        return wenv_error_set(err, WENV_ERR_IO, "cannot read OpenEXR file '%s': %s", path, stream.message);
    if (use_rgba) /* OpenEXRCore lacks this compression: OpenEXR's C++ library decodes the file */
        return load_exr_rgba(path, out, out_h, out_w, err);
    return err->status;
}
