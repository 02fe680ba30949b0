/* e57_cv.h — the records of one compressed vector (a scan's points), read packet by packet.
 *
 * The binary section at the scan's fileOffset starts with a 32-byte header: sectionId (1),
 * 7 reserved bytes, sectionLogicalLength, dataPhysicalOffset, indexPhysicalOffset (u64 LE).
 * Packets follow one another from dataPhysicalOffset to the section's end, each starting with
 * its type, flags and logical length - 1 (u8, u8, u16):
 *   data packet (type 1): bytestreamCount (u16, one per prototype field), the length of each
 *     field's buffer (u16 each), then the buffers;
 *   index packet (0) and empty packet (2): skipped.
 * A packet is at most 64 KiB; the buffers of one field over all data packets form its
 * bytestream (e57_bitpack.h). Fields advance independently (a writer may put more of one
 * field in a packet than of another), so each field keeps its own place in the packet sequence
 * and takes the next packet's buffer when its decoder runs dry; eight packets are cached so
 * the fields that follow read a packet from memory. Memory: a packet buffer per field read and
 * the cache, whatever the record count. Fields nobody asks for are never read. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "e57_pages.h"
#include "e57_scan.h"
#include "sd_err.h"

typedef struct e57_cv e57_cv;

/* e57_cv_open: the compressed vector of scan s (s and f outlive it). Checks the section header:
 * id 1, the section inside the file, the data packets inside the section. Returns 0, or
 * SD_EFORMAT / SD_ETRUNC naming the physical offset and the scan, SD_ENOMEM, SD_EIO. A scan of
 * 0 records still has its header checked. */
int e57_cv_open(e57_file *f, const e57_scan *s, e57_cv **out, sd_err *err);
void e57_cv_close(e57_cv *cv);

/* e57_cv_logical_len: the section's logical length (bytes of packets the records may use). */
uint64_t e57_cv_logical_len(const e57_cv *cv);

/* e57_cv_read: the next up to n records: for each field i with cols[i] != NULL, its n values
 * (as doubles) into cols[i]; other fields are not read. Returns the count, 0 once all records
 * were read, or a negative SD_E* naming the scan, the field and the record (a stream that ends
 * early, a value over its field's maximum, a bad packet with its physical offset). */
int64_t e57_cv_read(e57_cv *cv, double *const *cols, size_t n, sd_err *err);

/* e57_cv_reads: physical packet reads so far (tests: the cache works). */
uint64_t e57_cv_reads(const e57_cv *cv);
