!> Geometry of one particle shape: the columns of the NIST geometry table.
!>
!> Usage:
!>     type(shape_geometry_type) :: g
!>     call compute_geometry(shape, g)                 ! every coefficient
!>     call compute_geometry(shape, g, nused=14)       ! truncated at degree 14
!>     call compute_geometry(shape, g, next=40)        ! thesis extent scan with N_ext = 40
module anm_geometry_properties
   use anm_core_kinds, only: wp, pi
   use anm_sh_expansion, only: sh_expansion_type, sh_truncate
   use anm_sh_grid, only: sh_grid_type, new_sh_grid
   use anm_geometry_integrals, only: surface_integrals
   use anm_geometry_extent, only: extent_scan, extent_refined
   use anm_geometry_dimensions, only: particle_dimensions
   use anm_geometry_radial_bound, only: radial_bound_type
   implicit none
   private

   public :: shape_geometry_type, compute_geometry, geometry_grid_size

   !> Geometric properties of a shape (body frame, lengths in the shape's units).
   type :: shape_geometry_type
      !> Expansion degree used.
      integer :: order = 0
      !> Volume.
      real(wp) :: volume = 0.0_wp
      !> Surface area.
      real(wp) :: area = 0.0_wp
      !> Diameter of the sphere of equal volume, (6 V / pi)^(1/3).
      real(wp) :: equiv_diameter = 0.0_wp
      !> Area relative to that sphere, S / (pi d^2).
      real(wp) :: norm_area = 0.0_wp
      !> Trace of the inertia tensor about the centroid over that of the equal-volume sphere.
      real(wp) :: itrace = 0.0_wp
      !> Centroid (body frame).
      real(wp) :: centroid(3) = 0.0_wp
      !> Extent box: lowest and highest x, y, z of the surface, from the centre.
      real(wp) :: extent_lo(3) = 0.0_wp, extent_hi(3) = 0.0_wp
      !> Length, width, thickness.
      real(wp) :: length = 0.0_wp, width = 0.0_wp, thickness = 0.0_wp
      !> Unit directions of L, W, T.
      real(wp) :: dir_length(3) = 0.0_wp, dir_width(3) = 0.0_wp, dir_thickness(3) = 0.0_wp
      !> Smallest and largest radius found on the quadrature grid.
      real(wp) :: rmin = 0.0_wp, rmax = 0.0_wp
   end type shape_geometry_type

contains

   !> Number of polar nodes used for a degree: the thesis' 120-point rule, more for degree > 60.
   elemental function geometry_grid_size(order) result(ntheta)
      !> Expansion degree.
      integer, intent(in) :: order
      integer :: ntheta
      ntheta = max(120, 2 * order + 2)
   end function geometry_grid_size

   !> Compute every property of `shape` truncated at degree `nused` (default: all coefficients).
   !> Extents use the refined search unless `next` (thesis N_ext scan) is given.
   subroutine compute_geometry(shape, geom, nused, next, ntheta, bound)
      !> Particle shape.
      type(sh_expansion_type), intent(in) :: shape
      !> Result.
      type(shape_geometry_type), intent(out) :: geom
      !> Degree to use.
      integer, intent(in), optional :: nused
      !> Thesis extent scan with N_ext angles (default: refined extents).
      integer, intent(in), optional :: next
      !> Polar nodes of the quadrature grid (default geometry_grid_size(order)); nphi = 2 ntheta.
      integer, intent(in), optional :: ntheta
      !> Certified radius bounds of the shape at the order used (anm_contact_body, radial_bound):
      !> the same dimensions, found faster.
      type(radial_bound_type), intent(in), optional :: bound
      type(sh_expansion_type) :: s
      type(sh_grid_type) :: grid
      integer :: nt
      real(wp) :: inertia, rsph

      geom%order = shape%nmax
      if (present(nused)) geom%order = max(0, min(nused, shape%nmax))
      s = sh_truncate(shape, geom%order)
      nt = geometry_grid_size(geom%order)
      if (present(ntheta)) nt = ntheta
      grid = new_sh_grid(nt, 2 * nt, max(2, geom%order))
      call surface_integrals(grid, s, geom%volume, geom%area, geom%centroid, inertia, geom%rmin, geom%rmax)
      geom%equiv_diameter = (6.0_wp * geom%volume / pi)**(1.0_wp / 3.0_wp)
      geom%norm_area = geom%area / (pi * geom%equiv_diameter**2)
      rsph = 0.5_wp * geom%equiv_diameter
      geom%itrace = inertia / (2.0_wp * 0.6_wp * geom%volume * rsph**2)
      if (present(next)) then
         call extent_scan(s, next, geom%extent_lo, geom%extent_hi)
      else
         call extent_refined(s, grid, geom%extent_lo, geom%extent_hi)
      end if
      call particle_dimensions(s, grid, geom%length, geom%width, geom%thickness, &
                               geom%dir_length, geom%dir_width, geom%dir_thickness, bound)
   end subroutine compute_geometry
end module anm_geometry_properties
