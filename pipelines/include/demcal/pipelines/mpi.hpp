// The MPI evaluation backend: `mpirun -n N demcal calibrate ... --backend mpi`. Rank 0 runs the
// optimiser, the archive and the objectives; ranks 1..N-1 simulate. Tasks go out one at a time to
// whichever worker is free (dynamic balance); outcomes come back as JSON plus the curve values as
// raw doubles, so the curves are bit-identical to a local run and the same seed gives the same
// result as the threads backend. With N = 1, rank 0 simulates itself.
#pragma once

#include "demcal/pipelines/backend.hpp"

#include <memory>
#include <vector>

namespace demcal::pipelines {

// True when this build has MPI (DEMCAL_HAVE_MPI).
bool mpi_compiled();

// MPI_Init_thread on construction (funneled), MPI_Finalize on destruction. Throws
// std::runtime_error when the build has no MPI.
class MpiSession {
 public:
  MpiSession(int* argc, char*** argv);
  ~MpiSession();
  MpiSession(const MpiSession&) = delete;
  MpiSession& operator=(const MpiSession&) = delete;
  int rank() const { return rank_; }
  int size() const { return size_; }

 private:
  int rank_ = 0;
  int size_ = 1;
};

// Rank 0's backend; `scenes` per case (the workers build the same from the same campaign).
// Destroying it tells the workers to stop.
std::unique_ptr<EvaluationBackend> make_mpi_backend(std::vector<dem::Scene> scenes);

// Ends every rank of the job (rank 0 failed before the workers could be told to stop).
[[noreturn]] void mpi_abort(int code);

// Ranks > 0: simulate tasks from rank 0 until it says stop.
void mpi_serve(const std::vector<dem::Scene>& scenes);

}  // namespace demcal::pipelines
