!> Surface and volume integrals of a star-shaped SH particle by Gauss quadrature on the sphere:
!> volume, surface area, centroid and the trace of the inertia tensor.
!>
!> With r(theta, phi) and x = r rhat, over the unit sphere (solid angle dOmega):
!>     V = int r^3/3 dOmega,   c = int r^4/4 rhat dOmega / V,   int |x|^2 dV = int r^5/5 dOmega,
!>     S = int r sqrt(r^2 + r_theta^2 + (r_phi/sin theta)^2) dOmega.
!> The Gauss grid integrates V exactly for degree N when ntheta > (3N+1)/2 and nphi > 3N.
!>
!> Usage:
!>     call surface_integrals(grid, shape, vol, area, centroid, inertia_trace)
module anm_geometry_integrals
   use anm_core_kinds, only: wp
   use anm_sh_expansion, only: sh_expansion_type
   use anm_sh_grid, only: sh_grid_type, sh_synthesize
   implicit none
   private

   public :: surface_integrals

contains

   !> Volume, area, centroid (body frame) and trace of the inertia tensor about the centroid
   !> (2 int |x - c|^2 dV, unit density), truncated at degree nused when given.
   pure subroutine surface_integrals(grid, shape, volume, area, centroid, inertia_trace, rmin, rmax, nused)
      !> Quadrature grid (lmax >= degree used).
      type(sh_grid_type), intent(in) :: grid
      !> Particle.
      type(sh_expansion_type), intent(in) :: shape
      !> Volume.
      real(wp), intent(out) :: volume
      !> Surface area.
      real(wp), intent(out) :: area
      !> Centroid in the body frame.
      real(wp), intent(out) :: centroid(3)
      !> Trace of the inertia tensor about the centroid.
      real(wp), intent(out) :: inertia_trace
      !> Smallest and largest radius on the grid.
      real(wp), intent(out) :: rmin, rmax
      !> Degree at which to truncate.
      integer, intent(in), optional :: nused
      real(wp), allocatable :: r(:, :), rt(:, :), rp(:, :)
      real(wp) :: w, rr, m1(3), r5, st
      integer :: i, j, nt, np

      nt = grid%sphere%ntheta
      np = grid%sphere%nphi
      allocate (r(nt, np), rt(nt, np), rp(nt, np))
      call sh_synthesize(grid, shape, r, rt, rp, nused)
      volume = 0.0_wp
      area = 0.0_wp
      m1 = 0.0_wp
      r5 = 0.0_wp
      do j = 1, np
         do i = 1, nt
            w = grid%sphere%weight(i)
            rr = r(i, j)
            st = grid%sphere%sint(i)
            volume = volume + w * rr**3 / 3.0_wp
            area = area + w * rr * sqrt(rr * rr + rt(i, j)**2 + rp(i, j)**2)
            m1 = m1 + w * rr**4 / 4.0_wp * [st * grid%trig(2, j), st * grid%trig(grid%lmax + 2, j), grid%sphere%x(i)]
            r5 = r5 + w * rr**5 / 5.0_wp
         end do
      end do
      centroid = m1 / volume
      inertia_trace = 2.0_wp * (r5 - volume * sum(centroid**2))
      rmin = minval(r)
      rmax = maxval(r)
   end subroutine surface_integrals
end module anm_geometry_integrals
