/* The calling thread's number and its team's size in an OpenMP parallel region (0 and 1 without OpenMP);
 * shared by the matchers' C kernels (_census_sgm.h, _speckle.h). */
#ifndef VPP_OMP_TEAM_H
#define VPP_OMP_TEAM_H

#ifdef _OPENMP
#include <omp.h>
#endif

static inline void vpp_omp_team(int* tid, int* team) {
#ifdef _OPENMP
    *tid = omp_get_thread_num();
    *team = omp_get_num_threads();
#else
    *tid = 0;
    *team = 1;
#endif
}

#endif
