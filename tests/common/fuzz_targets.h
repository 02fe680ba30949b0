/* fuzz_targets.h — the bodies of the fuzz targets, shared by the libFuzzer wrappers
 * (tests/fuzz/fuzz_*.c, built with clang by tests/fuzz/run.sh) and by the regression test
 * tests/test_fuzz_regress.c (built with gcc by make test), which replays every corpus and
 * crash file through the same functions.
 *
 * Each fuzz_one_<target> takes arbitrary bytes and must never crash, leak or touch memory it
 * does not own. Beyond "no crash" each checks properties that hold for any input (oracles):
 * a failure returns a negative code with a non-empty message; what parsed re-encodes to the
 * same bytes; what a reader accepted fits in what the file can hold; two decoders agree. A
 * broken property prints what broke to stderr and calls abort(), which both libFuzzer and
 * cmocka report as a failure.
 *
 * Return value: 0 when the input was accepted as valid, a negative code when it was rejected
 * (SD_E* for the file readers and LZF, -PROTO_E_* for the protocol, -1 for parameters). The
 * libFuzzer wrappers ignore it; the regression test checks it for the hand-made seeds. */
#pragma once
#include <stddef.h>
#include <stdint.h>

/* fuzz_one_proto: byte 0 configures a proto_decoder (bits 0-1 accept_dir, bit 2 preauth,
 * bit 3 fixed version 1, bit 4 a 4 MiB payload limit, bits 5-7 the feed chunk size); the
 * rest is a byte stream fed to proto_decode in chunks and, separately, all at once (both
 * must give the same messages and error). Each message is parsed by its proto_parse_* and,
 * when it parses, re-encoded by its proto_enc_* and compared byte for byte. Returns 0 when
 * the whole stream decoded and every message parsed, else the first negative code. */
int fuzz_one_proto(const uint8_t *data, size_t len);

/* fuzz_one_ply / pcd / las / xyz: the bytes as a file (a memfd, read through
 * /proc/self/fd/N) given to pc_read_<fmt>, then pc_finalize. Returns the reader's or
 * pc_finalize's code. */
int fuzz_one_ply(const uint8_t *data, size_t len);
int fuzz_one_pcd(const uint8_t *data, size_t len);
int fuzz_one_las(const uint8_t *data, size_t len);
int fuzz_one_xyz(const uint8_t *data, size_t len);

/* fuzz_one_lzf: bytes 0-2 (little-endian, low 20 bits) are the declared output size, the
 * rest an LZF stream given to pc_lzf_decompress with an exactly sized output buffer. A plain
 * reference decoder must agree on success and on the bytes. Returns its code. */
int fuzz_one_lzf(const uint8_t *data, size_t len);

/* fuzz_one_params: the bytes (up to the first NUL) as a "name=value" string for
 * sp_param_set_kv on the defaults. On success the stored value must print and read back
 * (sp_param_get_text, sp_param_set_text) to within the printing precision; on failure the
 * parameters must be unchanged and the message non-empty. Returns 0 or -1. */
int fuzz_one_params(const uint8_t *data, size_t len);

/* fuzz_one_laz: as fuzz_one_las, through pc_read_laz (LAZ and COPC; chunks on threads). */
int fuzz_one_laz(const uint8_t *data, size_t len);

/* fuzz_one_copc: the COPC hierarchy reader (tests/common/fuzz_copc.c): bytes 0-159 are the
 * COPC info VLR payload, the whole input the file its offsets point into. copc_visit walks
 * every page; the nodes' counts must be >= 0 and each page entry inside the input. Returns
 * 0 or copc_visit's negative code. */
int fuzz_one_copc(const uint8_t *data, size_t len);

/* fuzz_one_cache: the bytes as a prep-cache file (cache.c) for a small source file, sealed
 * (cache__seal: the source's key and the checksums made to match what the file holds) and
 * loaded by cache__load with the default k. A loaded cache must have the layout's block length
 * inside its mapping and batches tiling its points; a refusal must say why. Returns 0 when
 * loaded, SD_EUNSUP when out of date, SD_ESTALE when damaged. */
int fuzz_one_cache(const uint8_t *data, size_t len);

/* fuzz_one_splod: the bytes as a LOD cache file (lod_file.c) for a small source file, sealed
 * (lod__seal: the source's key, the options of the seeds' build and the table and header
 * checksums made to match) and loaded by lod_load_file. A loaded cache must be a tree whose
 * nodes lie inside the file with counts adding up; every node's data is then copied and
 * checked (lod_node_copy: 0 or SD_ESTALE with a message). Returns 0 when loaded, SD_EUNSUP
 * when out of date, SD_ESTALE when damaged. */
int fuzz_one_splod(const uint8_t *data, size_t len);

/* fuzz_one_frame: byte 0 picks the format (bits 0-1: JPEG, LZ4, raw, PNG) and, with bit 2,
 * that the rest after bytes 1-2 is a whole FRAME payload (proto_parse_frame gives format and
 * size); else bytes 1-2 are the announced width and height (0: none) and the rest the image.
 * fd_decode (the client's decoder) must give an image of the announced size whose every byte
 * is readable, or a code with a message. Returns fd_decode's code (or the parse's). */
int fuzz_one_frame(const uint8_t *data, size_t len);

/* fuzz_one_dispatch (tests/common/fuzz_dispatch.c, linked only where the whole server is):
 * the bytes as what one client sends to the daemon's session and dispatch code, in this
 * process, on the real renderer (frames at most 128x128, one 64-point cloud "sphere"
 * prepared). The connection is served until the daemon closes it or falls quiet (at most 1 s),
 * then the client goes. Everything the daemon sent must decode and parse with the protocol's
 * own client-side code, and the session must be freed once the client has gone. Returns 0, or
 * minus the code of the first ERROR the daemon sent. */
int fuzz_one_dispatch(const uint8_t *data, size_t len);

/* fuzz_parse_msg: one decoded message through its proto_parse_* and, when it parses, the
 * re-encoding check (an oracle failure aborts). Returns the parser's code. */
typedef struct proto_msg proto_msg;
int fuzz_parse_msg(const proto_msg *m);

/* fuzz_one_e57: the bytes as an E57 file (its page checksums made to match first, so that
 * inputs get past page 0) through pc_read_e57 and pc_finalize, as fuzz_one_las. */
int fuzz_one_e57(const uint8_t *data, size_t len);

/* fuzz_one_e57xml: byte 0 picks a piece size (1-64); the rest is an E57 XML section fed to
 * e57_xml in pieces and at once (both must agree), then e57_desc_read. What is accepted must
 * be consistent: each role at a field of that role, bit widths those of the bounds, an
 * orthonormal rotation. Returns 0 or the negative code. */
int fuzz_one_e57xml(const uint8_t *data, size_t len);

/* fuzz_one_e57bits: byte 0 the bit width (0-64), byte 1 the kind (integer, scaled, float,
 * double), byte 2 how far the maximum lies below 2^width - 1, byte 3 the piece size, byte 4 the
 * value count of a 0-bit field; the rest a bytestream, appended to an e57_bp in pieces and
 * decoded whole, against a bit-at-a-time reference decoder, values and the first value over
 * the maximum alike. Returns 0, or SD_EFORMAT when a value was over the maximum. */
int fuzz_one_e57bits(const uint8_t *data, size_t len);

/* fuzz_one_copclevels: byte 0's low 3 bits are a level L, the rest a COPC file (a memfd)
 * read by pc_read_copc_levels(L) (io_copc.c), with the readers' checks (fuzz_one_las). When it
 * reads n points of levels 0..L' (its format string says L' <= L) and the whole hierarchy
 * reads too (levels 0..24, what the budget reader walks), pc_read_copc_budget(n) must keep
 * levels 0..L' and the same points in the same order, and pc_read_copc_budget(n - 1) a
 * shallower level and fewer points (or, where L' is the only level read, the same). Returns
 * pc_read_copc_levels' or pc_finalize's code. */
int fuzz_one_copclevels(const uint8_t *data, size_t len);

/* fuzz_one_lodsrc (fuzz_lodsrc.c): byte 0's low 3 bits pick the file's extension (.ply .las
 * .laz .pcd .xyz .pts .txt .copc.laz), its high 5 bits the piece size of the reads; the rest is
 * the file, opened by lod_src_open (the LOD build's stream: its own PLY header parser, the
 * LAS/LAZ/COPC, PCD and XYZ streams, else pc_load). What it opens must stream exactly info.n
 * finite points inside its box, the same again after lod_src_rewind, and be what pc_load reads
 * of the file: the same count, box, offset, float positions and colours (white without).
 * Returns lod_src's code. */
int fuzz_one_lodsrc(const uint8_t *data, size_t len);

/* fuzz_one_campath (fuzz_cli.c): the first line (to '\n' or NUL) is an output pattern for
 * cp_pattern_check and cp_expand, compared with an independent reading of campath.h's grammar
 * for five frame numbers, in a buffer of exactly the room the name needs and one byte less;
 * the rest is a camera-path file for cp_load (a memfd), which must give the cameras
 * cp_parse_line gives line by line, or fail naming the file and the first bad line; each
 * camera must print and parse back to itself. Returns cp_load's code. */
int fuzz_one_campath(const uint8_t *data, size_t len);

/* fuzz_one_shard (fuzz_cli.c): byte 0's bits 0-6 say which of --shard, --shards,
 * JOB_COMPLETION_INDEX, SPLAT_SHARD_COUNT, SLURM_ARRAY_TASK_ID, SLURM_ARRAY_TASK_COUNT and
 * SLURM_ARRAY_TASK_MIN are set; the rest holds their values, '\n'-separated. shard_resolve must
 * agree with an independent reading of shard.h's rules (digits only, each range, the order of
 * precedence), name the option or variable it refuses, and shard_filter keep exactly the frames
 * of its shard. Returns shard_resolve's code. */
int fuzz_one_shard(const uint8_t *data, size_t len);

/* fuzz_one_token (fuzz_cli.c): byte 0 bits 0-1 give the file's mode (0600 0400 0640 0604),
 * bit 2 reads it through a symbolic link, bit 3 puts a directory in its place, bit 4 a FIFO;
 * the rest is the token file. The daemon's auth_token_load and the client's spc__read_token
 * (room for AUTH_TOKEN_MAX bytes) must both accept exactly a regular file that group and others
 * cannot use, of at most AUTH_TOKEN_MAX + 2 bytes, whose content less its trailing CR and LF
 * is 1 to AUTH_TOKEN_MAX bytes, and give those bytes. Returns auth_token_load's code. */
int fuzz_one_token(const uint8_t *data, size_t len);

/* fuzz_one_mpimsg (fuzz_mpi.c): byte 0 bit 0 set: the rest is a failure record for
 * mr_fail_decode (server/mpi/mr_msg.h), which must give an SD_E* code and a terminated
 * message (the record's own when it has one); clear: the rest is a command record for
 * mr_cmd_decode, as received (any length but MR_CMD_BYTES refused) and padded with zeros or
 * cut to MR_CMD_BYTES. What decodes must hold what its op needs and re-encode (mr_cmd_encode)
 * to a record that decodes to the same command. Returns mr_cmd_decode's code (0 for a failure
 * record). */
int fuzz_one_mpimsg(const uint8_t *data, size_t len);

/* fuzz_target_find: the fuzz_one_* function of a target name ("proto", "ply", "pcd", "las",
 * "xyz", "lzf", "params", "laz", "copc", "ws", "cache", "splod", "frame", "e57", "e57xml",
 * "e57bits", "copclevels", "lodsrc", "campath", "shard", "token", "mpimsg"; "dispatch" where
 * the server is linked), or NULL. */
typedef int (*fuzz_fn)(const uint8_t *data, size_t len);
fuzz_fn fuzz_target_find(const char *name);

/* fuzz_one_ws: byte 0 configures a ws_decoder (bits 0-2: the piece size 2^k, bit 3
 * require_mask, bit 4 binary_only, bits 5-7 one of eight max_message values); the rest goes
 * through ws_decode all at once and in pieces with a 7-byte output buffer, which must give the
 * same payload bytes, events and error (a close code 1002/1003/1009 with a text); then through
 * http_parse_request, whose answer must be a complete head, "more" below 8 KiB, or a status
 * 400/414/431/505 with a text. Returns 0 when the stream decoded without error, else minus
 * the close code. */
int fuzz_one_ws(const uint8_t *data, size_t len);

/* ---- helpers for the bodies in the other tests/common/fuzz_*.c files ---- */

/* fuzz_fail: prints "fuzz oracle failed (where): ..." to stderr and aborts. */
void fuzz_fail(const char *where, const char *fmt, ...) __attribute__((format(printf, 2, 3),
                                                                      noreturn));
/* fuzz_check_sd_err: a reader's failure rc (0: none) is a known SD_E* code whose message in
 * err names path; else fuzz_fail for what. */
typedef struct sd_err sd_err;
void fuzz_check_sd_err(int rc, const sd_err *err, const char *path, const char *what);
/* fuzz_params_equal: 1 when a and b hold the same value of every parameter (params.h). */
typedef struct sp_params sp_params;
int fuzz_params_equal(const sp_params *a, const sp_params *b);
/* fuzz_memfd: data as a memfd; path (plen bytes) gets "/proc/self/fd/N". Returns the fd. */
int fuzz_memfd(const uint8_t *data, size_t len, char *path, size_t plen);
/* fuzz_mkdtemp: a new directory "splatd-fuzz-TAG.XXXXXX" in /dev/shm (else $TMPDIR, else
 * /tmp) into dir. fuzz_write_file: path := data. Both abort on failure (the harness's). */
void fuzz_mkdtemp(char *dir, size_t len, const char *tag);
void fuzz_write_file(const char *path, const void *data, size_t len);
