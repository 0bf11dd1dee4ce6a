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

   include "anm_cross.inc"
end module anm_core_vector
