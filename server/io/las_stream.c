/* las_stream.c — uncompressed LAS records read in blocks (las_stream.h). */
#include "las_stream.h"

#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "las_header.h"

enum { HEADER_READ = 375 }; /* the LAS 1.4 public header, the longest */

struct pc_las_stream {
    int fd;
    las_header h;
    char path[4096];
    char format[32];
    uint8_t *buf; /* PC_LAS_STREAM_BLOCK records */
};

int pc_las_stream_open(const char *path, pc_las_stream **out, sd_err *err)
{
    *out = NULL;
    pc_las_stream *s = calloc(1, sizeof *s);
    if (!s) return sd_errf(err, SD_ENOMEM, "out of memory");
    snprintf(s->path, sizeof s->path, "%s", path);
    s->fd = open(path, O_RDONLY | O_CLOEXEC | O_NONBLOCK);
    int rc = 0;
    struct stat st;
    uint8_t hdr[HEADER_READ] = {0};
    if (s->fd < 0) {
        rc = sd_errf(err, SD_EIO, "%s: %s", path, strerror(errno));
    } else if (fstat(s->fd, &st) < 0 || !S_ISREG(st.st_mode)) {
        rc = sd_errf(err, SD_EIO, "%s: not a regular file", path);
    } else {
        ssize_t got = pread(s->fd, hdr, sizeof hdr, 0);
        if (got < 0)
            rc = sd_errf(err, SD_EIO, "%s: %s", path, strerror(errno));
        else if (got < 4 || memcmp(hdr, "LASF", 4) != 0)
            rc = 0; /* not LAS */
        else if ((rc = pc__las_header(path, hdr, (size_t)st.st_size, &s->h, err)) == 0)
            rc = s->h.compressed ? 0 : 1;
    }
    if (rc == 1) {
        s->buf = malloc((size_t)PC_LAS_STREAM_BLOCK * s->h.rec_len);
        if (!s->buf) rc = sd_errf(err, SD_ENOMEM, "out of memory");
    }
    if (rc != 1) {
        pc_las_stream_close(s);
        return rc;
    }
    snprintf(s->format, sizeof s->format, "LAS 1.%u format %u", s->h.minor, s->h.format);
    *out = s;
    return 1;
}

void pc_las_stream_close(pc_las_stream *s)
{
    if (!s) return;
    if (s->fd >= 0) close(s->fd);
    free(s->buf);
    free(s);
}

uint64_t pc_las_stream_count(const pc_las_stream *s)
{
    return s->h.count;
}

int pc_las_stream_has_rgb(const pc_las_stream *s)
{
    return pc__las_formats[s->h.format].rgb != 0;
}

const char *pc_las_stream_format(const pc_las_stream *s)
{
    return s->format;
}

int pc_las_stream_read(pc_las_stream *s, uint64_t first, size_t m, double *xyz, uint16_t *rgb16,
                       sd_err *err)
{
    if (m > PC_LAS_STREAM_BLOCK || first > s->h.count || m > s->h.count - first)
        return sd_errf(err, SD_EINVAL, "%s: records %llu + %zu asked of %llu", s->path,
                       (unsigned long long)first, m, (unsigned long long)s->h.count);
    size_t len = m * s->h.rec_len, done = 0;
    uint64_t at = s->h.data_off + first * s->h.rec_len;
    while (done < len) {
        ssize_t g = pread(s->fd, s->buf + done, len - done, (off_t)(at + done));
        if (g < 0 && errno == EINTR) continue;
        if (g <= 0)
            return sd_errf(err, SD_EIO, "%s: %s at byte %llu", s->path,
                           g < 0 ? strerror(errno) : "the file ended (it changed)",
                           (unsigned long long)(at + done));
        done += (size_t)g;
    }
    unsigned rgb = pc__las_formats[s->h.format].rgb;
    for (size_t i = 0; i < m; i++) {
        const uint8_t *p = s->buf + i * s->h.rec_len;
        for (int k = 0; k < 3; k++)
            xyz[3 * i + k] = rdi32(p + 4 * k) * s->h.scale[k] + s->h.offset[k];
        if (rgb && rgb16)
            for (int k = 0; k < 3; k++) rgb16[3 * i + k] = rd16(p + rgb + 2 * k);
    }
    return 0;
}
