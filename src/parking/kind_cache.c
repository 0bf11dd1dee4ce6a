/* Hashes for the on-disk kind cache (src/parking/kind_cache.f90): a 64-bit FNV-1a-style hash of a memory
 * block and of a whole file (the running executable: the cache's code version). Unsigned
 * arithmetic wraps in C; Fortran has no unsigned integers. */
#include <stdint.h>
#include <stdio.h>
#include <stddef.h>
#include <string.h>

#define ANM_FNV_OFFSET 14695981039346656037ULL
#define ANM_FNV_PRIME 1099511628211ULL

/* FNV-1a of n bytes at p, continuing from h (pass 0 to start), taken 8 bytes at a time (a
 * 64-bit word per step, 8 times faster than byte steps on megabyte payloads; the tail bytewise).
 * Not the standard FNV-1a digest, only a checksum and a file name. */
uint64_t anm_fnv1a(const void *p, int64_t n, uint64_t h)
{
    const unsigned char *b = (const unsigned char *)p;
    int64_t i = 0;
    if (h == 0) h = ANM_FNV_OFFSET;
    for (; i + 8 <= n; i += 8) {
        uint64_t w;
        memcpy(&w, b + i, 8);
        h ^= w;
        h *= ANM_FNV_PRIME;
        h ^= h >> 29;
    }
    for (; i < n; i++) {
        h ^= b[i];
        h *= ANM_FNV_PRIME;
    }
    return h;
}

/* FNV-1a of the whole file `path`; 0 when it cannot be read. */
uint64_t anm_fnv1a_file(const char *path)
{
    unsigned char buf[65536];
    size_t got;
    uint64_t h = ANM_FNV_OFFSET;
    FILE *f = fopen(path, "rb");
    if (!f) return 0;
    while ((got = fread(buf, 1, sizeof buf, f)) > 0) h = anm_fnv1a(buf, (int64_t)got, h);
    if (ferror(f)) h = 0;
    fclose(f);
    return h;
}
