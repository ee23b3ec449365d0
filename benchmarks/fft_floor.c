/* The FFT-pair floor: one FFTW-MPI r2c plus one c2r 2D transform of an N x N field.
 *
 * Every solver iteration of petgap needs at least this pair, so its median time
 * is the unit in which benchmarks/contact.py and benchmarks/fft_pair.py state
 * petgap's costs.  Plans use FFTW_MEASURE and the transposed Fourier layout
 * (FFTW_MPI_TRANSPOSED_OUT / _IN), the cheapest pair FFTW-MPI offers.
 *
 * Usage: mpirun -n P fft_floor N [repeats]
 * Prints on rank 0: fft_floor N=<N> ranks=<P> median_pair_s=<seconds>
 * Built on first use by benchmarks/floor.py (mpicc, -lfftw3_mpi -lfftw3).
 */
#include <fftw3-mpi.h>
#include <stdio.h>
#include <stdlib.h>

static int by_value(const void *a, const void *b) {
  double x = *(const double *)a, y = *(const double *)b;
  return (x > y) - (x < y);
}

int main(int argc, char **argv) {
  MPI_Init(&argc, &argv);
  fftw_mpi_init();
  int rank, size;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  if (argc < 2) {
    if (rank == 0) fprintf(stderr, "usage: fft_floor N [repeats]\n");
    MPI_Abort(MPI_COMM_WORLD, 2);
  }
  const ptrdiff_t n = atol(argv[1]);
  const int repeats = argc > 2 ? atoi(argv[2]) : 15;
  if (n < 2 || repeats < 1) {
    if (rank == 0) fprintf(stderr, "fft_floor: N >= 2 and repeats >= 1 needed\n");
    MPI_Abort(MPI_COMM_WORLD, 2);
  }
  const ptrdiff_t nk = n / 2 + 1;
  ptrdiff_t local_n0, start0, local_n1, start1;
  const ptrdiff_t alloc = fftw_mpi_local_size_2d_transposed(
      n, nk, MPI_COMM_WORLD, &local_n0, &start0, &local_n1, &start1);
  double *real = fftw_alloc_real(2 * alloc);
  fftw_complex *fourier = fftw_alloc_complex(alloc);
  fftw_plan forward = fftw_mpi_plan_dft_r2c_2d(
      n, n, real, fourier, MPI_COMM_WORLD, FFTW_MEASURE | FFTW_MPI_TRANSPOSED_OUT);
  fftw_plan backward = fftw_mpi_plan_dft_c2r_2d(
      n, n, fourier, real, MPI_COMM_WORLD, FFTW_MEASURE | FFTW_MPI_TRANSPOSED_IN);
  /* Planning with FFTW_MEASURE overwrites the arrays: fill them afterwards. */
  srand(1 + rank);
  for (ptrdiff_t i = 0; i < local_n0; ++i)
    for (ptrdiff_t j = 0; j < 2 * nk; ++j)
      real[i * 2 * nk + j] = j < n ? (double)rand() / RAND_MAX : 0.0;
  double *times = malloc(sizeof(double) * repeats);
  for (int k = -2; k < repeats; ++k) { /* two untimed pairs first */
    MPI_Barrier(MPI_COMM_WORLD);
    const double t0 = MPI_Wtime();
    fftw_execute(forward);
    fftw_execute(backward);
    MPI_Barrier(MPI_COMM_WORLD);
    const double t = MPI_Wtime() - t0;
    if (k >= 0) times[k] = t;
    /* Keep values bounded: the unnormalised pair multiplies them by n^2. */
    const double scale = 1.0 / ((double)n * (double)n);
    for (ptrdiff_t i = 0; i < local_n0 * 2 * nk; ++i) real[i] *= scale;
  }
  qsort(times, repeats, sizeof(double), by_value);
  if (rank == 0)
    printf("fft_floor N=%ld ranks=%d median_pair_s=%.6f\n", (long)n, size, times[repeats / 2]);
  fftw_destroy_plan(forward);
  fftw_destroy_plan(backward);
  fftw_free(real);
  fftw_free(fourier);
  free(times);
  fftw_mpi_cleanup();
  MPI_Finalize();
  return 0;
}
