!> The kinds' building shared by the MPI processes (anm_parking_kinds' `kind_exchange_type`): each
!> process builds its share of a list of kinds and sends each kind it built (in the kind cache's
!> payload format) to the others with one MPI_Bcast of its length and one of its bytes. A kind is
!> a few MB (4.5 MB with shells at order 14), far below MPI's 2 GiB count limit.
!>
!> Usage:
!>     call new_mpi_kinds(kx, MPI_COMM_WORLD)      ! the distributor's kinds_exchange does this
module anm_mpi_kinds
   use, intrinsic :: iso_fortran_env, only: int8, int64
   use anm_parking_kinds, only: kind_exchange_type
   use mpi_f08, only: MPI_Comm, MPI_Bcast, MPI_Comm_rank, MPI_Comm_size, MPI_BYTE, MPI_INTEGER8
   implicit none
   private

   public :: mpi_kinds_type, new_mpi_kinds

   !> The exchange over a communicator.
   type, extends(kind_exchange_type) :: mpi_kinds_type
      !> Communicator.
      type(MPI_Comm) :: comm
   contains
      procedure :: broadcast
   end type mpi_kinds_type

contains

   !> An exchange over `comm`.
   subroutine new_mpi_kinds(kx, comm)
      !> Exchange.
      type(mpi_kinds_type), intent(out) :: kx
      !> Communicator.
      type(MPI_Comm), intent(in) :: comm
      kx%comm = comm
      call MPI_Comm_rank(comm, kx%rank)
      call MPI_Comm_size(comm, kx%nranks)
   end subroutine new_mpi_kinds

   !> Process root's bytes to every process (collective).
   subroutine broadcast(self, root, b)
      !> Exchange.
      class(mpi_kinds_type), intent(in) :: self
      !> Sending process.
      integer, intent(in) :: root
      !> The bytes: given on root, received on the others.
      integer(int8), allocatable, intent(inout) :: b(:)
      integer(int64) :: n
      if (self%rank == root) n = size(b, kind=int64)
      call MPI_Bcast(n, 1, MPI_INTEGER8, root, self%comm)
      if (self%rank /= root) then
         if (allocated(b)) deallocate (b)
         allocate (b(n))
      end if
      call MPI_Bcast(b, int(n), MPI_BYTE, root, self%comm)
   end subroutine broadcast
end module anm_mpi_kinds
