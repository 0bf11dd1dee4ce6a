!> Text shown to users from untrusted sources (file contents, attributes): control and non-ASCII
!> bytes replaced, long text shortened, so that no message prints raw bytes.
!>
!> Usage:
!>     msg = "format = '"//printable(fmt)//"'"
module anm_core_text
   implicit none
   private

   public :: printable

contains

   !> `text` with every byte outside printable ASCII (32..126) shown as `?` and, beyond `limit`
   !> characters (default 60), cut with "..." appended.
   pure function printable(text, limit) result(shown)
      !> Text from a file.
      character(len=*), intent(in) :: text
      !> Longest text shown.
      integer, intent(in), optional :: limit
      character(len=:), allocatable :: shown
      integer :: n, i, c
      n = 60
      if (present(limit)) n = max(4, limit)
      if (len(text) <= n) then
         shown = text
      else
         shown = text(1:n - 3)//"..."
      end if
      do i = 1, len(shown)
         c = iachar(shown(i:i))
         if (c < 32 .or. c > 126) shown(i:i) = "?"
      end do
   end function printable
end module anm_core_text
