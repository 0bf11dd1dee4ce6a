!> The `anm` command of the MPI build (mpi/, scripts/build_mpi.sh): `mpirun -np N anm run FILE.nml`
!> parks on every process (anm_mpi_distributor: phase 1 of each batch spread over the processes
!> and their threads); all processes write the model file together through parallel HDF5
!> (anm_mpi_output) and rank 0 renames it and writes the summary and VRML: the same model as the
!> serial program. `anm verify` is distributed too (each process audits the pairs of its slab,
!> anm_mpi_verify). The other commands run on rank 0 alone, as in the serial program. Exit codes as
!> app/main.f90 (docs/cli.md); an error on any process aborts the job (MPI_Abort).
program anm_mpi
   use, intrinsic :: iso_fortran_env, only: output_unit, error_unit
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_core_filesystem, only: string_type
   use anm_cli_arguments, only: command_arguments
   use anm_cli_commands, only: write_usage, shape_command, synth_command, verify_command, study_command
   use anm_cli_run, only: run_job, anm_version
   use anm_core_output, only: ignore_file_size_signal
   use anm_mpi_distributor, only: mpi_distributor_type, new_mpi_distributor, write_comm_stats
   use anm_mpi_output, only: mpi_output_type, new_mpi_output
   use anm_mpi_verify, only: mpi_verify_type, new_mpi_verify
   use mpi_f08, only: MPI_Init_thread, MPI_Finalize, MPI_Abort, MPI_COMM_WORLD, MPI_THREAD_FUNNELED
   use omp_lib, only: omp_get_max_threads
   implicit none

   type(string_type), allocatable :: args(:)
   type(error_type), allocatable :: error
   type(mpi_distributor_type) :: dist
   type(mpi_output_type) :: io
   type(mpi_verify_type) :: split
   integer :: status, provided, k
   character(len=:), allocatable :: nml
   logical :: force, stats, replicated

   ! MPI is called outside the OpenMP regions only
   call MPI_Init_thread(MPI_THREAD_FUNNELED, provided)
   call ignore_file_size_signal()
   args = command_arguments()
   ! `anm run FILE.nml [--force] [--comm-stats] [--replicated]`: --comm-stats prints what was
   ! communicated; --replicated parks with the whole packing on every process instead of slabs
   stats = .false.
   replicated = .false.
   do k = 2, size(args)
      if (args(1)%s == "run" .and. args(k)%s == "--comm-stats") stats = .true.
      if (args(1)%s == "run" .and. args(k)%s == "--replicated") replicated = .true.
   end do
   call new_mpi_distributor(dist, MPI_COMM_WORLD, omp_get_max_threads(), count=stats, replicated=replicated)
   call new_mpi_output(io, MPI_COMM_WORLD)
   call new_mpi_verify(split, MPI_COMM_WORLD)
   if (size(args) < 1) then
      if (dist%writer) call write_usage(error_unit)
      call finish(2)
   end if
   status = 0
   if (args(1)%s == "run") then
      force = .false.
      do k = 2, size(args)
         select case (args(k)%s)
         case ("--force")
            force = .true.
         case ("--comm-stats", "--replicated")
         case default
            if (allocated(nml) .or. args(k)%s(1:min(1, len(args(k)%s))) == "-") then
               call fatal_error(error, "usage: anm run FILE.nml [--force] [--comm-stats] [--replicated]", error_code%usage)
               exit
            end if
            nml = args(k)%s
         end select
      end do
      if (.not. allocated(nml) .and. .not. allocated(error)) &
         call fatal_error(error, "usage: anm run FILE.nml [--force] [--comm-stats] [--replicated]", error_code%usage)
      if (.not. allocated(error)) then
         call run_job(nml, output_unit, error_unit, error, omp_get_max_threads(), force=force, dist=dist, par=io)
         if (stats .and. .not. allocated(error)) call write_comm_stats(dist, error_unit)
      end if
   else if (args(1)%s == "verify") then
      ! every process audits its slab; rank 0 writes the combined report
      call verify_command(args(2:), output_unit, status, error, split=split)
   else if (dist%writer) then
      select case (args(1)%s)
      case ("-h", "--help", "help")
         call write_usage(output_unit)
         write (output_unit, '(a)') "", "MPI build (docs/mpi.md): mpirun -np N anm run FILE.nml [--force] [--comm-stats] " &
            //"[--replicated]", &
            "        --comm-stats: what was communicated, per sieve, and the peak memory per rank (stderr)", &
            "        --replicated: every rank holds the whole packing (default: slabs along x, each rank", &
            "        its slab and halo; the dense strategy always runs replicated); the model is the same", &
            "  mpirun -np N anm verify MODEL.h5 [options]: each rank audits the pairs of its slab"
      case ("--version")
         write (output_unit, '(a)') "anm "//anm_version//" (MPI)"
      case ("shape")
         call shape_command(args(2:), output_unit, error)
      case ("synth")
         call synth_command(args(2:), output_unit, error)
      case ("study")
         call study_command(args(2:), output_unit, error)
      case default
         call fatal_error(error, "unknown command '"//args(1)%s//"' (try: anm --help)", error_code%value)
      end select
   end if
   if (allocated(error)) then
      write (error_unit, '(a)') "anm: error: "//error%message
      flush (error_unit)
      ! the other processes may wait in a collective call
      call MPI_Abort(MPI_COMM_WORLD, 1)
   end if
   call finish(status)

contains

   !> End MPI and exit with `code`.
   subroutine finish(code)
      integer, intent(in) :: code
      call MPI_Finalize()
      if (code /= 0) call exit(code)
      stop
   end subroutine finish
end program anm_mpi
