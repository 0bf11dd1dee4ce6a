!> The `anm` command: parses the command line, calls the library (anm_cli_run, anm_cli_commands)
!> and turns errors into messages and exit codes (docs/cli.md): 0 success, 1 error (the message on
!> stderr), 2 usage error (no command, unknown command or option, missing argument), 3 `anm verify`
!> found an overlap. `anm COMMAND --help` prints the command's usage on stdout.
program anm
   use, intrinsic :: iso_fortran_env, only: output_unit, error_unit
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_core_filesystem, only: string_type
   use anm_cli_arguments, only: command_arguments, wants_help
   use anm_cli_commands, only: write_usage, write_command_usage, shape_command, synth_command, verify_command, &
      & study_command
   use anm_cli_run, only: run_command, rerun_command, anm_version
   use anm_core_output, only: ignore_file_size_signal
   use omp_lib, only: omp_get_max_threads
   implicit none

   type(string_type), allocatable :: args(:)
   type(error_type), allocatable :: error
   integer :: status
   logical :: found

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
   case ("--version", "-V")
      write (output_unit, '(a)') "anm "//anm_version
   case default
      if (wants_help(args(2:))) then
         call write_command_usage(output_unit, args(1)%s, found)
         if (found) then
            write (output_unit, '(a)') "", "Details: docs/cli.md, docs/user-guide.md."
            call exit(0)
         end if
      end if
      select case (args(1)%s)
      case ("shape")
         call shape_command(args(2:), output_unit, error)
      case ("synth")
         call synth_command(args(2:), output_unit, error)
      case ("verify")
         call verify_command(args(2:), output_unit, status, error)
      case ("study")
         call study_command(args(2:), output_unit, error)
      case ("run")
         call run_command(args(2:), output_unit, error_unit, error, omp_get_max_threads())
      case ("rerun")
         call rerun_command(args(2:), output_unit, error_unit, error, omp_get_max_threads())
      case default
         call fatal_error(error, "unknown command '"//args(1)%s//"' (try: anm --help)", error_code%usage)
      end select
   end select
   if (allocated(error)) then
      write (error_unit, '(a)') "anm: error: "//error%message
      if (error%stat == error_code%usage) then
         write (error_unit, '(a)') "(anm "//command_word(args(1)%s)//"--help: usage)"
         call exit(2)
      end if
      call exit(1)
   end if
   if (status /= 0) call exit(status)

contains

   !> The command followed by a blank, or nothing for an unknown command.
   function command_word(command) result(word)
      character(len=*), intent(in) :: command
      character(len=:), allocatable :: word
      select case (command)
      case ("run", "rerun", "verify", "shape", "synth", "study")
         word = command//" "
      case default
         word = ""
      end select
   end function command_word
end program anm
