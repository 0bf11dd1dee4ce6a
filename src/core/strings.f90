!> Small string helpers used to build error messages and tables.
!>
!> Usage:
!>     msg = "line " // to_string(12) // ": value " // to_string(1.5_wp)
module anm_core_strings
   use anm_core_kinds, only: wp, i8
   implicit none
   private

   public :: to_string, to_lower

   !> Convert a number to its shortest readable text.
   interface to_string
      module procedure :: int_to_string
      module procedure :: long_to_string
      module procedure :: real_to_string
   end interface to_string

contains

   !> Default integer as text.
   pure function int_to_string(val) result(str)
      !> Value to convert.
      integer, intent(in) :: val
      character(len=:), allocatable :: str
      character(len=24) :: buf
      write (buf, '(i0)') val
      str = trim(buf)
   end function int_to_string

   !> 64-bit integer as text.
   pure function long_to_string(val) result(str)
      !> Value to convert.
      integer(i8), intent(in) :: val
      character(len=:), allocatable :: str
      character(len=24) :: buf
      write (buf, '(i0)') val
      str = trim(buf)
   end function long_to_string

   !> Real as text with up to 8 significant digits.
   pure function real_to_string(val) result(str)
      !> Value to convert.
      real(wp), intent(in) :: val
      character(len=:), allocatable :: str
      character(len=32) :: buf
      write (buf, '(g0.8)') val
      str = trim(adjustl(buf))
   end function real_to_string

   !> Lower-case copy of an ASCII string.
   pure function to_lower(str) result(low)
      !> Text to convert.
      character(len=*), intent(in) :: str
      character(len=len(str)) :: low
      integer :: i, c
      low = str
      do i = 1, len(str)
         c = iachar(str(i:i))
         if (c >= iachar('A') .and. c <= iachar('Z')) low(i:i) = achar(c + 32)
      end do
   end function to_lower
end module anm_core_strings
