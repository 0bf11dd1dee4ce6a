!> Kind parameters and mathematical constants shared by every Anm module.
!>
!> Usage:
!>     use anm_core_kinds, only: wp, pi
!>     real(wp) :: x = 2.0_wp * pi
module anm_core_kinds
   use, intrinsic :: iso_fortran_env, only: int32, int64
   implicit none
   private

   public :: wp, sp, i4, i8, pi, two_pi, four_pi, inv_sqrt_4pi

   !> Working precision: IEEE double.
   integer, parameter :: wp = selected_real_kind(15)
   !> Single precision (compact storage of outward-rounded bounds).
   integer, parameter :: sp = selected_real_kind(6)
   !> 32-bit integer kind.
   integer, parameter :: i4 = int32
   !> 64-bit integer kind (random number generator state, large counts).
   integer, parameter :: i8 = int64
   !> The circle constant.
   real(wp), parameter :: pi = 3.14159265358979323846264338327950288_wp
   !> 2 pi.
   real(wp), parameter :: two_pi = 2.0_wp * pi
   !> 4 pi, the solid angle of the sphere.
   real(wp), parameter :: four_pi = 4.0_wp * pi
   !> 1 / sqrt(4 pi), the spherical harmonic Y_0^0 (the seed of the Legendre recurrences).
   real(wp), parameter :: inv_sqrt_4pi = 0.28209479177387814347403972578038630_wp
end module anm_core_kinds
