/* e57_pages.h — the physical layer of an E57 file (ASTM E2807): the 48-byte file header and
 * the checksummed pages.
 *
 * An E57 file is a sequence of pages of page_size bytes; the last 4 bytes of each page are the
 * CRC-32C (Castagnoli) of the page's other bytes, stored big-endian. The bytes without the
 * checksums form the "logical" stream; every offset the file records (the XML section's, a
 * compressed vector's, a data packet's) is physical, so a logical run may cross pages. Every
 * page is checked when it is read: a mismatch is an error naming the page's physical offset.
 *
 * The header (logical bytes 0-47 of page 0): "ASTM-E57", major and minor version (u32),
 * filePhysicalLength, xmlPhysicalOffset, xmlLogicalLength, pageSize (u64), all little-endian. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "sd_err.h"

enum { E57_HEADER_BYTES = 48, E57_CRC_BYTES = 4 };

typedef struct e57_file {
    int fd;
    char *path;
    uint64_t size;           /* the file's physical length (fstat) */
    uint64_t page;           /* page size, physical bytes; page - 4 logical bytes each */
    uint64_t xml_off;        /* physical offset of the XML section */
    uint64_t xml_len;        /* its logical length */
    uint32_t major, minor;
    uint32_t crc_table[256]; /* CRC-32C, reflected polynomial 0x82F63B78 */
    int hw_crc;              /* the CPU has SSE4.2's crc32 instruction */
    /* the read buffer: up to E57_READ_PAGES pages per pread, the last page kept checked */
    uint8_t *buf;
    uint64_t cached_page;    /* index of the checked page held at cache; UINT64_MAX: none */
    uint8_t *cache;
    uint64_t pages_checked;  /* pages whose CRC was computed (tests: each is read once) */
} e57_file;

enum { E57_READ_PAGES = 64 };

/* e57_file_open: opens path and checks the header: signature, version 1, a page size of at
 * least 64 bytes that is a multiple of 4, filePhysicalLength equal to the file's size and a
 * whole number of pages, page 0's checksum, the XML section inside the file. Returns 0, or
 * SD_EFORMAT (not E57 / bad header), SD_EUNSUP (another major version), SD_ETRUNC (shorter than
 * the header says), SD_EIO, SD_ENOMEM, each naming path and the offset. */
int e57_file_open(const char *path, e57_file *f, sd_err *err);
void e57_file_close(e57_file *f);

/* e57_file_read: len logical bytes starting at physical offset phys into out, every page they
 * touch read and its checksum checked. phys must not point into a checksum. Returns 0, or
 * SD_EFORMAT (a checksum mismatch, naming the page's physical offset; an offset inside a
 * checksum), SD_ETRUNC (the run goes past the file's end), SD_EIO. */
int e57_file_read(e57_file *f, uint64_t phys, void *out, size_t len, sd_err *err);

/* e57_phys_advance: the physical offset len logical bytes after physical offset phys (which
 * must not point into a checksum); UINT64_MAX on overflow. */
uint64_t e57_phys_advance(const e57_file *f, uint64_t phys, uint64_t len);

/* e57_logical_room: logical bytes from physical offset phys to the end of the file (0 when phys
 * is past it). */
uint64_t e57_logical_room(const e57_file *f, uint64_t phys);

/* e57_crc32c: CRC-32C of n bytes (the table of f, or the instruction where the CPU has it).
 * e57__crc32c_table: the table form alone (the tests compare the two). */
uint32_t e57_crc32c(const e57_file *f, const uint8_t *p, size_t n);
uint32_t e57__crc32c_table(const uint32_t table[256], const uint8_t *p, size_t n);
void e57__crc32c_init(uint32_t table[256]);
