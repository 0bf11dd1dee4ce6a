!> `anm verify` over MPI processes: every process reads the model and audits the pairs of its slab
!> along x (anm_audit_verify's `verify_split_type`); the reports are combined here: pair, overlap
!> and wall counts summed, the largest penetration the largest over the processes, the deepest
!> pair that of the process holding the deepest one. Every process ends with the serial report.
!>
!> Usage:
!>     call new_mpi_verify(split, MPI_COMM_WORLD)
!>     call verify_command(args(2:), output_unit, status, error, split=split)
module anm_mpi_verify
   use, intrinsic :: iso_fortran_env, only: int64
   use anm_core_kinds, only: wp
   use anm_audit_verify, only: verify_split_type, verify_report_type
   use mpi_f08, only: MPI_Comm, MPI_Comm_rank, MPI_Comm_size, MPI_Allreduce, MPI_Bcast, MPI_INTEGER8, MPI_INTEGER, &
                      MPI_DOUBLE_PRECISION, MPI_2DOUBLE_PRECISION, MPI_SUM, MPI_MAX, MPI_MAXLOC
   implicit none
   private

   public :: mpi_verify_type, new_mpi_verify

   !> The processes of a communicator auditing one model.
   type, extends(verify_split_type) :: mpi_verify_type
      !> Communicator.
      type(MPI_Comm) :: comm
   contains
      procedure :: reduce
   end type mpi_verify_type

contains

   !> Audit over `comm` (collective).
   subroutine new_mpi_verify(split, comm)
      !> Distributed audit.
      type(mpi_verify_type), intent(out) :: split
      !> Communicator.
      type(MPI_Comm), intent(in) :: comm
      split%comm = comm
      call MPI_Comm_rank(comm, split%rank)
      call MPI_Comm_size(comm, split%nranks)
   end subroutine new_mpi_verify

   !> The report of all processes (collective).
   subroutine reduce(self, report)
      !> Distributed audit.
      class(mpi_verify_type), intent(in) :: self
      !> This process' report on entry; the combined one on return.
      type(verify_report_type), intent(inout) :: report
      integer(int64) :: mine(4), all(4)
      real(wp) :: deepest(2), found(2), depth
      integer :: owner
      mine = [report%pairs_checked, report%pairs_cleared, report%overlapping_pairs, int(report%wall_violations, int64)]
      call MPI_Allreduce(mine, all, 4, MPI_INTEGER8, MPI_SUM, self%comm)
      report%pairs_checked = all(1)
      report%pairs_cleared = all(2)
      report%overlapping_pairs = all(3)
      report%wall_violations = int(all(4))
      call MPI_Allreduce(report%max_depth, depth, 1, MPI_DOUBLE_PRECISION, MPI_MAX, self%comm)
      report%max_depth = depth
      ! the deepest pair between particles: the process holding it (the lowest on a tie) tells it
      deepest = [report%worst_depth, real(self%rank, wp)]
      call MPI_Allreduce(deepest, found, 1, MPI_2DOUBLE_PRECISION, MPI_MAXLOC, self%comm)
      owner = nint(found(2))
      call MPI_Bcast(report%worst, 2, MPI_INTEGER, owner, self%comm)
      report%worst_depth = found(1)
   end subroutine reduce
end module anm_mpi_verify
