!> Error handling: a procedure that can fail takes
!> `type(error_type), allocatable, intent(out) :: error` as its last argument and allocates it
!> with a message naming the file, line, variable or dataset and the offending value.
!>
!> Usage:
!>     call fatal_error(error, "shapes.dat:12: expected 4 fields, found 3")
!>     if (allocated(error)) return
module anm_core_error
   implicit none
   private

   public :: error_type, fatal_error, error_code

   !> Numeric codes that classify errors (the message is what users read).
   type :: error_code_enum
      !> Unclassified failure.
      integer :: generic = 1
      !> Input/output failure: missing file, unreadable file.
      integer :: io = 2
      !> Malformed input: wrong field count, non-numeric value, truncated file.
      integer :: format = 3
      !> A value outside its valid range.
      integer :: value = 4
      !> A shape that is not star-shaped (r <= 0 somewhere).
      integer :: not_star = 5
      !> A usage error on the command line: unknown command or option, a missing argument or
      !> option value, an option value of the wrong type or range (`anm` exits with status 2).
      integer :: usage = 6
   end type error_code_enum

   !> The error classes, used as `error_code%format`.
   type(error_code_enum), parameter :: error_code = error_code_enum()

   !> An error raised by a library routine and returned to its caller.
   type :: error_type
      !> Error class, one of `error_code`.
      integer :: stat = 1
      !> Human-readable message naming what is wrong and where.
      character(len=:), allocatable :: message
   end type error_type

contains

   !> Allocate `error` with a message and an optional class.
   pure subroutine fatal_error(error, message, stat)
      !> The error to create.
      type(error_type), allocatable, intent(out) :: error
      !> What went wrong, naming the file / variable / line.
      character(len=*), intent(in) :: message
      !> Error class from `error_code` (default: generic).
      integer, intent(in), optional :: stat

      allocate (error)
      error%message = message
      if (present(stat)) then
         error%stat = stat
      else
         error%stat = error_code%generic
      end if
   end subroutine fatal_error
end module anm_core_error
