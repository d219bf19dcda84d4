// Whether this process was started by an MPI launcher, from the environment the launcher sets,
// so that the same binary calls MPI_Init only then (it costs about 0.4 s per process with
// OpenMPI 4.1 here, and a plain run must not pay it). Compiled in every build: a build without
// MPI uses it to refuse a launch it cannot serve.
//
//   OMPI_COMM_WORLD_SIZE         OpenMPI's mpirun / mpiexec
//   PMIX_RANK                    PMIx launchers (OpenMPI 4+, `srun --mpi=pmix`)
//   PMI_RANK, PMI_SIZE           PMI-1/PMI-2 launchers (`srun --mpi=pmi2`, MPICH's hydra)
//   SLURM_PROCID with SLURM_STEP_NUM_TASKS > 1
//                                a job step of several tasks started by srun. Not SLURM_NTASKS:
//                                an sbatch script runs as one process with SLURM_NTASKS set to
//                                the allocation's task count, and must not call MPI_Init.
#pragma once

#include <cstdlib>
#include <string>

namespace isotile {

inline bool launched_by_mpi() {
  auto set = [](const char* name) {
    const char* v = std::getenv(name);
    return v != nullptr && *v != '\0';
  };
  if (set("OMPI_COMM_WORLD_SIZE") || set("PMIX_RANK") || set("PMI_RANK") || set("PMI_SIZE"))
    return true;
  const char* tasks = std::getenv("SLURM_STEP_NUM_TASKS");
  return set("SLURM_PROCID") && tasks != nullptr && std::atol(tasks) > 1;
}

// The task count the launcher announced (0 when it says none): a launcher that started several
// tasks which MPI then sees as one each (srun without a PMI plugin) is an error, not K
// independent runs writing one file.
inline long launcher_task_count() {
  for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "SLURM_STEP_NUM_TASKS"})
    if (const char* v = std::getenv(name); v != nullptr && *v != '\0') return std::atol(v);
  return 0;
}

}  // namespace isotile
