!> The command line as a list of strings, and typed option values read from it with messages that
!> name the option and the offending text (docs/cli.md).
!>
!> Usage:
!>     args = command_arguments()               ! args(1) is the command
!>     call int_option(args, i, "--order", order, error, minimum=0)
module anm_cli_arguments
   use anm_core_kinds, only: wp
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_core_strings, only: to_string
   use anm_core_filesystem, only: string_type
   implicit none
   private

   public :: command_arguments, option_text, int_option, real_option, is_option, wants_help

contains

   !> Every argument of the command line, in order (the program name excluded).
   function command_arguments() result(args)
      type(string_type), allocatable :: args(:)
      integer :: i, length
      allocate (args(command_argument_count()))
      do i = 1, size(args)
         call get_command_argument(i, length=length)
         allocate (character(len=length) :: args(i)%s)
         if (length > 0) call get_command_argument(i, args(i)%s)
      end do
   end function command_arguments

   !> Whether an argument looks like an option (starts with '-').
   pure function is_option(arg) result(yes)
      !> Argument.
      character(len=*), intent(in) :: arg
      logical :: yes
      yes = arg(1:min(1, len(arg))) == "-"
   end function is_option

   !> Whether `-h` or `--help` is among the arguments (then the command prints its usage).
   pure function wants_help(args) result(yes)
      !> Arguments after the command name.
      type(string_type), intent(in) :: args(:)
      logical :: yes
      integer :: i
      yes = .false.
      do i = 1, size(args)
         if (args(i)%s == "-h" .or. args(i)%s == "--help") yes = .true.
      end do
   end function wants_help

   !> Text of the value of option `name` (args(i+1)), checked against the allowed characters;
   !> advances i past the value.
   pure subroutine option_text(args, i, name, allowed, what, text, error)
      !> Arguments.
      type(string_type), intent(in) :: args(:)
      !> Position of the option; on return, of its value.
      integer, intent(inout) :: i
      !> Option name, allowed characters of its value, what the value must be (for messages).
      character(len=*), intent(in) :: name, allowed, what
      !> Value text.
      character(len=:), allocatable, intent(out) :: text
      !> Error naming the option and the text.
      type(error_type), allocatable, intent(out) :: error
      if (i + 1 > size(args)) then
         call fatal_error(error, "option "//name//" needs a value", error_code%usage)
         return
      end if
      text = args(i + 1)%s
      if (len(text) == 0 .or. verify(text, allowed) /= 0) then
         call fatal_error(error, "option "//name//": '"//text//"' is not "//what, error_code%usage)
         return
      end if
      i = i + 1
   end subroutine option_text

   !> Integer value of option `name` (args(i+1)), at least `minimum` when given.
   subroutine int_option(args, i, name, val, error, minimum)
      !> Arguments.
      type(string_type), intent(in) :: args(:)
      !> Position of the option; on return, of its value.
      integer, intent(inout) :: i
      !> Option name.
      character(len=*), intent(in) :: name
      !> Value.
      integer, intent(inout) :: val
      !> Error naming the option and the text.
      type(error_type), allocatable, intent(out) :: error
      !> Smallest allowed value.
      integer, intent(in), optional :: minimum
      character(len=:), allocatable :: text
      integer :: stat
      call option_text(args, i, name, "+-0123456789", "an integer", text, error)
      if (allocated(error)) return
      read (text, *, iostat=stat) val
      if (stat /= 0) then
         call fatal_error(error, "option "//name//": '"//text//"' is not an integer", error_code%usage)
      else if (present(minimum)) then
         if (val < minimum) call fatal_error(error, "option "//name//": "//to_string(val)//" must be >= " &
                                             //to_string(minimum), error_code%usage)
      end if
   end subroutine int_option

   !> Real value of option `name` (args(i+1)).
   subroutine real_option(args, i, name, val, error)
      !> Arguments.
      type(string_type), intent(in) :: args(:)
      !> Position of the option; on return, of its value.
      integer, intent(inout) :: i
      !> Option name.
      character(len=*), intent(in) :: name
      !> Value.
      real(wp), intent(inout) :: val
      !> Error naming the option and the text.
      type(error_type), allocatable, intent(out) :: error
      character(len=:), allocatable :: text
      integer :: stat
      call option_text(args, i, name, "+-.0123456789eEdD", "a number", text, error)
      if (allocated(error)) return
      read (text, *, iostat=stat) val
      if (stat /= 0) call fatal_error(error, "option "//name//": '"//text//"' is not a number", error_code%usage)
   end subroutine real_option
end module anm_cli_arguments
