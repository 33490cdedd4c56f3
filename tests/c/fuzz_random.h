/* The fuzz harnesses' random numbers: splitmix64 from a seed the harness sets in rng_state. */
#ifndef OPFMU_FUZZ_RANDOM_H
#define OPFMU_FUZZ_RANDOM_H

#include <stdint.h>

static uint64_t rng_state;

static inline uint64_t next_random(void) /* splitmix64 */
{
    uint64_t z = (rng_state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

/* uniform in 0 .. n - 1 */
static inline int below(int n) { return (int)(next_random() % (uint64_t)n); }

/* uniform in [0, 1) */
static inline double uniform(void) { return (double)(next_random() >> 11) / 9007199254740992.0; }

#endif
