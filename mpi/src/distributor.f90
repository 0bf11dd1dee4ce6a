!> Phase 1 of the parking's batches over MPI processes (replicated data, distributed speculation):
!> every process holds the whole packing; member b of a batch runs phase 1 on process
!> mod(b - 1, nranks) (with its threads), and the attempts (random stream state, counters, pose,
!> count) are gathered to every process with one MPI_Allgatherv. Phase 2 (in-order re-check and
!> accept) then runs identically on every process, so every process parks the serial model
!> (anm_parking_scheduler: any batch composition gives the serial result).
!>
!> Usage:
!>     call new_mpi_distributor(dist, MPI_COMM_WORLD, omp_get_max_threads())
!>     call run_job(path, output_unit, error_unit, error, threads, dist=dist)
module anm_mpi_distributor
   use, intrinsic :: iso_fortran_env, only: int8
   use anm_core_kinds, only: wp
   use anm_parking_attempts, only: attempt_type, attempt_params_type
   use anm_parking_packing, only: packing_type
   use anm_parking_void_grid, only: void_grid_type
   use anm_parking_scheduler, only: phase1_distributor_type, run_phase1
   use mpi_f08, only: MPI_Comm, MPI_Allgatherv, MPI_Allreduce, MPI_Comm_rank, MPI_Comm_size, MPI_BYTE, &
                      MPI_DOUBLE_PRECISION, MPI_INTEGER, MPI_MAX, MPI_SUM
   implicit none
   private

   public :: mpi_distributor_type, new_mpi_distributor

   !> Phase 1 over the processes of a communicator.
   type, extends(phase1_distributor_type) :: mpi_distributor_type
      !> Communicator, this process' rank and the number of processes.
      type(MPI_Comm) :: comm
      integer :: rank = 0, nranks = 1
   contains
      procedure :: phase1
      procedure :: agree
   end type mpi_distributor_type

contains

   !> A distributor over `comm` (collective): `threads` are this process' threads; the batches are
   !> sized for the threads of all processes; rank 0 writes.
   subroutine new_mpi_distributor(dist, comm, threads)
      !> Distributor.
      type(mpi_distributor_type), intent(out) :: dist
      !> Communicator.
      type(MPI_Comm), intent(in) :: comm
      !> Threads of this process.
      integer, intent(in) :: threads
      dist%comm = comm
      call MPI_Comm_rank(comm, dist%rank)
      call MPI_Comm_size(comm, dist%nranks)
      call MPI_Allreduce(max(1, threads), dist%workers, 1, MPI_INTEGER, MPI_SUM, comm)
      dist%writer = dist%rank == 0
   end subroutine new_mpi_distributor

   !> Phase 1 of a batch: this process' members (rank + 1, rank + 1 + nranks, ...), then every
   !> member's attempt gathered to every process (collective).
   subroutine phase1(self, at, ap, pk, vg, nstream)
      !> Distributor.
      class(mpi_distributor_type), intent(in) :: self
      !> Attempts of the batch.
      type(attempt_type), intent(inout) :: at(:)
      !> Parameters of the sieve.
      type(attempt_params_type), intent(in) :: ap
      !> Packing (frozen, the same on every process).
      type(packing_type), intent(in) :: pk
      !> Void grid.
      type(void_grid_type), intent(in) :: vg
      !> Particles of the sieve before this batch.
      integer, intent(in) :: nstream
      integer(int8), allocatable :: mine(:), all(:)
      integer, allocatable :: counts(:), displs(:)
      integer :: n, r, bytes, i, b
      n = size(at)
      if (self%nranks == 1) then
         call run_phase1(at, ap, pk, vg, nstream, 1, 1)
         return
      end if
      call run_phase1(at, ap, pk, vg, nstream, self%rank + 1, self%nranks)
      ! every process holds the same binary: an attempt travels as its bytes
      bytes = storage_size(at(1)) / 8
      allocate (counts(0:self%nranks - 1), displs(0:self%nranks - 1))
      do r = 0, self%nranks - 1
         counts(r) = members(n, r, self%nranks)
      end do
      displs(0) = 0
      do r = 1, self%nranks - 1
         displs(r) = displs(r - 1) + counts(r - 1)
      end do
      allocate (mine(counts(self%rank) * bytes), all(n * bytes))
      do i = 1, counts(self%rank)
         b = self%rank + 1 + (i - 1) * self%nranks
         mine((i - 1) * bytes + 1:i * bytes) = transfer(at(b), mine)
      end do
      call MPI_Allgatherv(mine, counts(self%rank) * bytes, MPI_BYTE, all, counts * bytes, displs * bytes, MPI_BYTE, &
                          self%comm)
      ! rank r's members are r + 1, r + 1 + nranks, ... in order
      do r = 0, self%nranks - 1
         do i = 1, counts(r)
            b = r + 1 + (i - 1) * self%nranks
            at(b) = transfer(all((displs(r) + i - 1) * bytes + 1:(displs(r) + i) * bytes), at(b))
         end do
      end do
   end subroutine phase1

   !> The largest x over the processes (collective).
   function agree(self, x) result(y)
      !> Distributor.
      class(mpi_distributor_type), intent(in) :: self
      !> This process' value.
      real(wp), intent(in) :: x
      real(wp) :: y
      call MPI_Allreduce(x, y, 1, MPI_DOUBLE_PRECISION, MPI_MAX, self%comm)
   end function agree

   !> Members of a batch of n on rank r of nranks (round robin).
   pure integer function members(n, r, nranks) result(m)
      integer, intent(in) :: n, r, nranks
      m = 0
      if (n > r) m = (n - r - 1) / nranks + 1
   end function members
end module anm_mpi_distributor
