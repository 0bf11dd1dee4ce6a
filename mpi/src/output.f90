!> Parallel HDF5 output of the MPI build: the processes of a communicator write one model file
!> together through MPI-IO (anm_io_hdf5's `h5_parallel_type`): the file is created and its
!> metadata written collectively, each process writes a block of the particle datasets
!> (hyperslabs of the last dimension, collective transfers), process 0 the small datasets.
!>
!> Usage:
!>     call new_mpi_output(io, MPI_COMM_WORLD)
!>     call run_job(path, output_unit, error_unit, error, threads, dist=dist, par=io)
module anm_mpi_output
   use hdf5, only: hid_t, h5pcreate_f, h5pset_fapl_mpio_f, h5pset_dxpl_mpio_f, H5P_FILE_ACCESS_F, &
                   H5P_DATASET_XFER_F, H5FD_MPIO_COLLECTIVE_F
   use anm_io_hdf5, only: h5_parallel_type
   use mpi_f08, only: MPI_Comm, MPI_Comm_rank, MPI_Comm_size, MPI_Bcast, MPI_Barrier, MPI_INTEGER, &
                      MPI_CHARACTER, MPI_INFO_NULL
   implicit none
   private

   public :: mpi_output_type, new_mpi_output

   !> The processes of a communicator writing one file together.
   type, extends(h5_parallel_type) :: mpi_output_type
      !> Communicator.
      type(MPI_Comm) :: comm
   contains
      procedure :: property_lists
      procedure :: share
      procedure :: barrier
   end type mpi_output_type

contains

   !> Parallel output over `comm` (collective).
   subroutine new_mpi_output(io, comm)
      !> Parallel output.
      type(mpi_output_type), intent(out) :: io
      !> Communicator.
      type(MPI_Comm), intent(in) :: comm
      io%comm = comm
      call MPI_Comm_rank(comm, io%rank)
      call MPI_Comm_size(comm, io%nranks)
   end subroutine new_mpi_output

   !> A file-access list with the MPI-IO driver on the communicator and a collective transfer list.
   subroutine property_lists(self, fapl, dxpl)
      !> Parallel output.
      class(mpi_output_type), intent(in) :: self
      !> File-access and data-transfer property lists.
      integer(hid_t), intent(out) :: fapl, dxpl
      integer :: st
      call h5pcreate_f(H5P_FILE_ACCESS_F, fapl, st)
      ! HDF5 1.10's Fortran interface takes the handles of the old mpi module
      call h5pset_fapl_mpio_f(fapl, self%comm%MPI_VAL, MPI_INFO_NULL%MPI_VAL, st)
      call h5pcreate_f(H5P_DATASET_XFER_F, dxpl, st)
      call h5pset_dxpl_mpio_f(dxpl, H5FD_MPIO_COLLECTIVE_F, st)
   end subroutine property_lists

   !> Process 0's text on every process (collective).
   subroutine share(self, text)
      !> Parallel output.
      class(mpi_output_type), intent(in) :: self
      !> Process 0's text on entry there; on return, the same everywhere.
      character(len=:), allocatable, intent(inout) :: text
      integer :: n
      n = 0
      if (self%rank == 0 .and. allocated(text)) n = len(text)
      call MPI_Bcast(n, 1, MPI_INTEGER, 0, self%comm)
      if (self%rank /= 0) then
         if (allocated(text)) deallocate (text)
         allocate (character(len=n) :: text)
      end if
      if (n > 0) call MPI_Bcast(text, n, MPI_CHARACTER, 0, self%comm)
   end subroutine share

   !> Wait for every process (collective).
   subroutine barrier(self)
      !> Parallel output.
      class(mpi_output_type), intent(in) :: self
      call MPI_Barrier(self%comm)
   end subroutine barrier
end module anm_mpi_output
