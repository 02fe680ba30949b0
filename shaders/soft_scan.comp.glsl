#version 430
#include "lib_bindings.glsl"
// soft_scan.comp — exclusive prefix sum of the soft compositor's u_ncells cell counts in place
// (one work group: each invocation sums a consecutive chunk, the chunk sums are scanned in
// shared memory, then each chunk is rewritten as offsets); cells[u_ncells] = the total.
layout(local_size_x = 256) in;
layout(std430, binding = B_SOFT_CELLS) buffer Cells { uint cells[]; };
uniform uint u_ncells;
shared uint sums[256];

void main()
{
    uint l = gl_LocalInvocationID.x;
    uint per = (u_ncells + 255u) / 256u;
    uint a = min(u_ncells, l * per), z = min(u_ncells, a + per);
    uint s = 0u;
    for (uint i = a; i < z; i++) s += cells[i];
    sums[l] = s;
    barrier();
    if (l == 0u) {
        uint run = 0u;
        for (uint i = 0u; i < 256u; i++) {
            uint v = sums[i];
            sums[i] = run;
            run += v;
        }
        cells[u_ncells] = run;
    }
    barrier();
    uint run = sums[l];
    for (uint i = a; i < z; i++) {
        uint v = cells[i];
        cells[i] = run;
        run += v;
    }
}
