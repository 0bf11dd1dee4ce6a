!> Small vector operations on 3-vectors shared by the geometry, contact, shell and slicing code.
!>
!> Usage:
!>     use anm_core_vector, only: cross
!>     n = cross(e1, e2)
module anm_core_vector
   use anm_core_kinds, only: wp
   implicit none
   private

   public :: cross

contains

   !> Cross product a x b.
   pure function cross(a, b) result(c)
      !> Vectors.
      real(wp), intent(in) :: a(3), b(3)
      real(wp) :: c(3)
      c = [a(2) * b(3) - a(3) * b(2), a(3) * b(1) - a(1) * b(3), a(1) * b(2) - a(2) * b(1)]
   end function cross
end module anm_core_vector
