// Philox4x32-10 counter-based random numbers (Salmon, Moraes, Dror, Shaw, "Parallel random
// numbers: as easy as 1, 2, 3", SC 2011; constants from Random123). Twin: kernels/philox.py.
#ifndef PHOTONLOOM_PHILOX_CL
#define PHOTONLOOM_PHILOX_CL

#define PHILOX_M0 0xD2511F53u
#define PHILOX_M1 0xCD9E8D57u
#define PHILOX_W0 0x9E3779B9u
#define PHILOX_W1 0xBB67AE85u

// One round on four scalar words: two 32x32 -> 64-bit products, a swap and a key xor. Scalars
// only (no uint4), so that PoCL's loop vectoriser can widen the work-group loop.
#define PHILOX_ROUND(c0, c1, c2, c3, k0, k1) do { \
        const ulong p0_ = (ulong)PHILOX_M0 * (ulong)(c0); \
        const ulong p1_ = (ulong)PHILOX_M1 * (ulong)(c2); \
        const uint n0_ = (uint)(p1_ >> 32) ^ (c1) ^ (k0); \
        const uint n2_ = (uint)(p0_ >> 32) ^ (c3) ^ (k1); \
        (c1) = (uint)p1_; (c3) = (uint)p0_; (c0) = n0_; (c2) = n2_; \
    } while (0)

#define PHILOX_BUMP(k0, k1) do { (k0) += PHILOX_W0; (k1) += PHILOX_W1; } while (0)

// Philox4x32-10 in place on the counter words c0..c3 with key (k0, k1) (key copied, not changed):
// ten rounds of ROUND (scalar here, eight lanes in lanes.cl) with the key bumped in between.
#define PHILOX_10(ROUND, c0, c1, c2, c3, key0, key1) do { \
        uint k0_ = (key0), k1_ = (key1); \
        ROUND(c0, c1, c2, c3, k0_, k1_); PHILOX_BUMP(k0_, k1_); \
        ROUND(c0, c1, c2, c3, k0_, k1_); PHILOX_BUMP(k0_, k1_); \
        ROUND(c0, c1, c2, c3, k0_, k1_); PHILOX_BUMP(k0_, k1_); \
        ROUND(c0, c1, c2, c3, k0_, k1_); PHILOX_BUMP(k0_, k1_); \
        ROUND(c0, c1, c2, c3, k0_, k1_); PHILOX_BUMP(k0_, k1_); \
        ROUND(c0, c1, c2, c3, k0_, k1_); PHILOX_BUMP(k0_, k1_); \
        ROUND(c0, c1, c2, c3, k0_, k1_); PHILOX_BUMP(k0_, k1_); \
        ROUND(c0, c1, c2, c3, k0_, k1_); PHILOX_BUMP(k0_, k1_); \
        ROUND(c0, c1, c2, c3, k0_, k1_); PHILOX_BUMP(k0_, k1_); \
        ROUND(c0, c1, c2, c3, k0_, k1_); \
    } while (0)
#define PHILOX4X32_10(c0, c1, c2, c3, key0, key1) PHILOX_10(PHILOX_ROUND, c0, c1, c2, c3, key0, key1)

inline uint4 philox4x32_10(uint4 c, uint2 k) {
    uint c0 = c.x, c1 = c.y, c2 = c.z, c3 = c.w;
    PHILOX4X32_10(c0, c1, c2, c3, k.x, k.y);
    return (uint4)(c0, c1, c2, c3);
}


#endif
