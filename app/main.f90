!> The `anm` command: parses the command line, calls the library (anm_cli_run, anm_cli_commands)
!> and turns errors into messages and exit codes (docs/cli.md): 0 success, 1 error (the message on
!> stderr), 2 no command given, 3 `anm verify` found an overlap.
program anm
   use, intrinsic :: iso_fortran_env, only: output_unit, error_unit
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_core_filesystem, only: string_type
   use anm_cli_arguments, only: command_arguments
   use anm_cli_commands, only: write_usage, shape_command, synth_command, verify_command, study_command
   use anm_cli_run, only: run_job, anm_version
   use anm_core_output, only: ignore_file_size_signal
   use omp_lib, only: omp_get_max_threads
   implicit none

   type(string_type), allocatable :: args(:)
   type(error_type), allocatable :: error
   integer :: status

   call ignore_file_size_signal()   ! a file-size limit gives EFBIG, reported as an error
   args = command_arguments()
   if (size(args) < 1) then
      call write_usage(error_unit)
      call exit(2)
   end if
   status = 0
   select case (args(1)%s)
   case ("-h", "--help", "help")
      call write_usage(output_unit)
   case ("--version")
      write (output_unit, '(a)') "anm "//anm_version
   case ("shape")
      call shape_command(args(2:), output_unit, error)
   case ("synth")
      call synth_command(args(2:), output_unit, error)
   case ("verify")
      call verify_command(args(2:), output_unit, status, error)
   case ("study")
      call study_command(args(2:), output_unit, error)
   case ("run")
      if (size(args) /= 2) then
         call fatal_error(error, "usage: anm run FILE.nml", error_code%value)
      else
         call run_job(args(2)%s, output_unit, error_unit, error, omp_get_max_threads())
      end if
   case default
      call fatal_error(error, "unknown command '"//args(1)%s//"' (try: anm --help)", error_code%value)
   end select
   if (allocated(error)) then
      write (error_unit, '(a)') "anm: error: "//error%message
      call exit(1)
   end if
   if (status /= 0) call exit(status)
end program anm
