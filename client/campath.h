/* campath.h — the testable parts of `splat path` (not part of the public library API):
 * camera-path files, output-name patterns, resuming, output files and the progress line. */
#pragma once
#include <stddef.h>
#include <stdint.h>

/* One camera of a path file. */
typedef struct cp_cam {
    double eye[3], target[3], up[3];
    float fov;                /* vertical, degrees */
} cp_cam;

/* cp_parse_line: one line of a camera-path file: ten numbers "eye x y z, target x y z,
 * up x y z, fov", separated by spaces, tabs and/or commas; '#' starts a comment. Returns 1 with
 * *cam set, 0 for a blank or comment-only line, -1 with err saying which number is wrong. */
int cp_parse_line(const char *line, cp_cam *cam, char *err, size_t errlen);

/* cp_load: every camera of the file at path into a malloc'd array (*cams, *n; free()).
 * Returns 0, or -1 with err naming the file and line (also for no cameras at all). */
int cp_load(const char *path, cp_cam **cams, size_t *n, char *err, size_t errlen);

/* cp_pattern_check: 0 when pattern holds exactly one integer conversion %d, %Nd or %0Nd
 * (N < 20), plus any number of "%%"; else -1 with err. Patterns are never handed to printf. */
int cp_pattern_check(const char *pattern, char *err, size_t errlen);

/* cp_expand: the file name for frame index (>= 0) of pattern ("out/%05d.jpg", 7 ->
 * "out/00007.jpg"). Returns 0, or -1 for a bad pattern or a result longer than len - 1. */
int cp_expand(const char *pattern, long index, char *out, size_t len);

/* cp_ext_format: the frame format a file name asks for by its extension (case-insensitive):
 * ".jpg"/".jpeg" -> "jpeg", ".png" -> "png", ".exr" -> "exr", ".raw" -> "raw"; else NULL. */
const char *cp_ext_format(const char *path);

/* cp_frame_done: 1 when path is a regular file of at least one byte (a frame written by an
 * earlier run: files are written under a temporary name and renamed, so a file that exists
 * is complete), else 0. */
int cp_frame_done(const char *path);

/* cp_todo: the indices in [0, n) whose output file (pattern) is not done yet, in order, into
 * todo (room for n). With force, all of them. Returns the count, or -1 for a bad pattern. */
long cp_todo(const char *pattern, long n, int force, long *todo);

/* cp_mkdirs: creates the directories leading to file path (like mkdir -p of its dirname).
 * Returns 0 or -1 with err. */
int cp_mkdirs(const char *path, char *err, size_t errlen);

/* cp_write_file: writes len bytes to path through "path.tmp.PID" + rename, so a reader (or a
 * resumed run) never sees a partial file. Returns 0 or -1 with err. */
int cp_write_file(const char *path, const void *data, size_t len, char *err, size_t errlen);

/* cp_progress_line: "[#####-----]  12/100  3.4 frames/s  ETA 0:26" (bar of `bar` characters,
 * none when bar = 0) for done of total after elapsed seconds. Returns buf. */
char *cp_progress_line(char *buf, size_t len, long done, long total, double elapsed, int bar);
