!> Exact analytic test shapes: spheres (order 0) and ellipsoids expanded to any order.
!>
!> Usage:
!>     sphere = sphere_shape(2.0_wp)                     ! radius 2
!>     ell = ellipsoid_shape(3.0_wp, 2.0_wp, 1.0_wp, 30)   ! semi-axes along x, y, z; degree 30
module anm_shapes_analytic
   use anm_core_kinds, only: wp, pi
   use anm_sh_expansion, only: sh_expansion_type, new_sh_expansion_real
   use anm_sh_grid, only: sh_grid_type, new_sh_grid, sh_analyze
   implicit none
   private

   public :: sphere_shape, ellipsoid_shape, ellipsoid_radius

contains

   !> Sphere of the given radius: the single coefficient a_00 = 2 sqrt(pi) R.
   pure function sphere_shape(radius) result(shape)
      !> Radius.
      real(wp), intent(in) :: radius
      type(sh_expansion_type) :: shape
      real(wp) :: a(0:0, 0:0), b(0:0, 0:0)
      a(0, 0) = 2.0_wp * sqrt(pi) * radius
      b = 0.0_wp
      call new_sh_expansion_real(shape, a, b)
   end function sphere_shape

   !> Radius of the ellipsoid x^2/a^2 + y^2/b^2 + z^2/c^2 = 1 along the unit direction u.
   pure function ellipsoid_radius(sa, sb, sc, u) result(r)
      !> Semi-axes along x, y, z.
      real(wp), intent(in) :: sa, sb, sc
      !> Unit direction.
      real(wp), intent(in) :: u(3)
      real(wp) :: r
      r = 1.0_wp / sqrt((u(1) / sa)**2 + (u(2) / sb)**2 + (u(3) / sc)**2)
   end function ellipsoid_radius

   !> Ellipsoid with semi-axes (sa, sb, sc) along (x, y, z), expanded to degree nmax by Gauss
   !> quadrature on a grid fine enough that aliasing is below the truncation error.
   pure function ellipsoid_shape(sa, sb, sc, nmax) result(shape)
      !> Semi-axes along x, y, z.
      real(wp), intent(in) :: sa, sb, sc
      !> Degree of the expansion.
      integer, intent(in) :: nmax
      type(sh_expansion_type) :: shape
      type(sh_grid_type) :: grid
      real(wp), allocatable :: f(:, :), a(:, :), b(:, :)
      integer :: i, j, nt

      nt = 2 * nmax + 64
      grid = new_sh_grid(nt, 2 * nt, nmax)
      allocate (f(nt, 2 * nt), a(0:nmax, 0:nmax), b(0:nmax, 0:nmax))
      do j = 1, 2 * nt
         do i = 1, nt
            f(i, j) = ellipsoid_radius(sa, sb, sc, &
                                       [grid%sphere%sint(i) * cos(grid%sphere%phi(j)), &
                                        grid%sphere%sint(i) * sin(grid%sphere%phi(j)), grid%sphere%x(i)])
         end do
      end do
      call sh_analyze(grid, f, nmax, a, b)
      call new_sh_expansion_real(shape, a, b)
   end function ellipsoid_shape
end module anm_shapes_analytic
