!> Gauss-Legendre quadrature of any order and the Gauss grid on the sphere
!> (Gauss-Legendre in cos(theta), equally spaced phi) used for all surface integrals.
!>
!> Usage:
!>     call gauss_legendre(120, x, w)      ! nodes in (-1, 1), weights summing to 2
!>     grid = new_sphere_grid(120, 240)    ! the thesis' 120-point rule
module anm_sh_quadrature
   use anm_core_kinds, only: wp, pi, two_pi
   implicit none
   private

   public :: gauss_legendre, sphere_grid_type, new_sphere_grid

   !> A product grid on the sphere: ntheta Gauss-Legendre nodes in x = cos(theta), nphi
   !> equally spaced azimuths. Integrates exactly any band-limited function of degree
   !> < min(2*ntheta, nphi).
   type :: sphere_grid_type
      !> Number of polar nodes.
      integer :: ntheta = 0
      !> Number of azimuthal nodes.
      integer :: nphi = 0
      !> cos(theta) at the polar nodes, decreasing from near +1 (north) to near -1.
      real(wp), allocatable :: x(:)
      !> Polar angles theta (radians), increasing.
      real(wp), allocatable :: theta(:)
      !> sin(theta) at the polar nodes.
      real(wp), allocatable :: sint(:)
      !> Azimuths phi_j = 2 pi (j-1) / nphi.
      real(wp), allocatable :: phi(:)
      !> Solid-angle weights w(i) * 2 pi / nphi; sum over the grid = 4 pi.
      real(wp), allocatable :: weight(:)
   end type sphere_grid_type

contains

   !> Nodes and weights of the n-point Gauss-Legendre rule on [-1, 1] (Newton on P_n from the
   !> Tricomi initial guess; accurate to rounding for any n >= 1). Nodes are returned in
   !> decreasing order.
   pure subroutine gauss_legendre(n, x, w)
      !> Number of nodes.
      integer, intent(in) :: n
      !> Nodes, decreasing.
      real(wp), allocatable, intent(out) :: x(:)
      !> Weights.
      real(wp), allocatable, intent(out) :: w(:)
      integer :: i, k, iter
      real(wp) :: z, p0, p1, p2, dp, dz

      allocate (x(n), w(n))
      do i = 1, (n + 1) / 2
         ! Tricomi's approximation to the i-th largest root
         z = (1.0_wp - (n - 1.0_wp) / (8.0_wp * real(n, wp)**3)) &
             * cos(pi * (4.0_wp * i - 1.0_wp) / (4.0_wp * n + 2.0_wp))
         do iter = 1, 100
            p0 = 1.0_wp
            p1 = z
            do k = 2, n
               p2 = ((2 * k - 1) * z * p1 - (k - 1) * p0) / k
               p0 = p1
               p1 = p2
            end do
            if (n == 1) p0 = 1.0_wp
            ! p1 = P_n(z), p0 = P_{n-1}(z)
            dp = n * (z * p1 - p0) / (z * z - 1.0_wp)
            dz = p1 / dp
            z = z - dz
            if (abs(dz) <= 4.0_wp * epsilon(z) * abs(z) .or. abs(dz) < tiny(z) * 1.0e10_wp) exit
         end do
         ! recompute the derivative at the converged root for the weight
         p0 = 1.0_wp
         p1 = z
         do k = 2, n
            p2 = ((2 * k - 1) * z * p1 - (k - 1) * p0) / k
            p0 = p1
            p1 = p2
         end do
         if (n == 1) p0 = 1.0_wp
         dp = n * (z * p1 - p0) / (z * z - 1.0_wp)
         x(i) = z
         x(n + 1 - i) = -z
         w(i) = 2.0_wp / ((1.0_wp - z * z) * dp * dp)
         w(n + 1 - i) = w(i)
      end do
      if (mod(n, 2) == 1) x((n + 1) / 2) = 0.0_wp
   end subroutine gauss_legendre

   !> Build a Gauss grid with ntheta polar and nphi azimuthal nodes.
   pure function new_sphere_grid(ntheta, nphi) result(grid)
      !> Number of Gauss-Legendre nodes in cos(theta).
      integer, intent(in) :: ntheta
      !> Number of equally spaced azimuths.
      integer, intent(in) :: nphi
      type(sphere_grid_type) :: grid
      real(wp), allocatable :: w(:)
      integer :: j

      grid%ntheta = ntheta
      grid%nphi = nphi
      call gauss_legendre(ntheta, grid%x, w)
      grid%theta = acos(grid%x)
      grid%sint = sqrt((1.0_wp - grid%x) * (1.0_wp + grid%x))
      grid%weight = w * (two_pi / nphi)
      allocate (grid%phi(nphi))
      do j = 1, nphi
         grid%phi(j) = two_pi * (j - 1) / real(nphi, wp)
      end do
   end function new_sphere_grid
end module anm_sh_quadrature
