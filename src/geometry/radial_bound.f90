!> A certified upper bound of a star-shaped surface's radius r(u) per cell of a cube map of
!> directions: a point farther from the centre than its cell's bound is outside the surface, which
!> a line march (anm_geometry_dimensions, chord_span) can then tell without evaluating r. The
!> bounds are filled from a certified patch hierarchy (anm_contact_body, `radial_bound`).
!>
!> The cube map is the support table's (anm_contact_body, support_cell): the face of a direction's
!> largest component, then the other two components over that one, in n equal steps each. The
!> point need not be a unit vector.
!>
!> Usage:
!>     if (surely_outside(rb, p, norm2(p))) ...   ! p outside: r(p/|p|) < |p|
module anm_geometry_radial_bound
   use anm_core_kinds, only: wp
   implicit none
   private

   public :: radial_bound_type, radial_cell, surely_outside

   !> Bounds per cube-map cell (n = 0: none; every test answers "not sure").
   type :: radial_bound_type
      !> Cells per face edge.
      integer :: n = 0
      !> Certified upper bound of r over the directions of each cell (6 n^2), shape units.
      real(wp), allocatable :: rmax(:)
   end type radial_bound_type

contains

   !> Cube-map cell (1..6 n^2) of a non-zero vector v (`cube_cell`).
   pure integer function radial_cell(n, v) result(c)
      !> Cells per face edge.
      integer, intent(in) :: n
      !> Direction (any length > 0).
      real(wp), intent(in) :: v(3)
      c = cube_cell(n, v)
   end function radial_cell

   !> True when the point p (|p| = len > 0) is certainly outside the surface: len exceeds its
   !> cell's bound by more than the rounding of an evaluated r(p/|p|) (1e-12 relative). False
   !> means "not known".
   pure logical function surely_outside(rb, p, len)
      !> Bounds.
      type(radial_bound_type), intent(in) :: rb
      !> Point (body frame, shape units) and its length.
      real(wp), intent(in) :: p(3), len
      surely_outside = .false.
      if (rb%n == 0 .or. len <= 0.0_wp) return
      surely_outside = len > rb%rmax(cube_cell(rb%n, p)) * (1.0_wp + 1.0e-12_wp)
   end function surely_outside

   include "anm_cube_cell.inc"
end module anm_geometry_radial_bound
