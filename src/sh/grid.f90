!> Fast synthesis of r(theta, phi) and its angular derivatives on a whole Gauss grid.
!>
!> Precomputes, once per grid, the Legendre values and derivatives on every ring and the
!> cos/sin(m phi) tables. Synthesis is then two dense products: per ring and order m the sum over
!> degree n (a small matrix-vector product), then per azimuth the sum over m (a matrix product of
!> (ntheta x (2L+1)) by ((2L+1) x nphi)). Cost O(ntheta L^2 + ntheta nphi L), never
!> (L+1)^2 terms per point.
!>
!> Usage:
!>     grid = new_sh_grid(120, 240, 30)
!>     call sh_synthesize(grid, shape, r)                       ! r(ntheta, nphi)
!>     call sh_synthesize(grid, shape, r, r_theta, r_phi_sin)   ! with derivatives
module anm_sh_grid
   use anm_core_kinds, only: wp
   use anm_sh_quadrature, only: sphere_grid_type, new_sphere_grid
   use anm_sh_legendre, only: legendre_table_type, new_legendre_table, legendre_values, &
      & legendre_theta_derivatives, packed_size
   use anm_sh_expansion, only: sh_expansion_type
   implicit none
   private

   public :: sh_grid_type, new_sh_grid, sh_synthesize, sh_analyze, sh_grid_normals

   !> Gauss grid with precomputed Legendre and trigonometric tables up to degree lmax
   !> (immutable after construction, shareable between threads).
   type :: sh_grid_type
      !> Nodes and weights.
      type(sphere_grid_type) :: sphere
      !> Highest degree the tables support.
      integer :: lmax = -1
      !> Packed offsets of order m (degree-lmax layout), m = 0..lmax+1.
      integer, allocatable :: idx(:)
      !> Pbar values, (packed (n,m), ring).
      real(wp), allocatable :: plm(:, :)
      !> d Pbar / d theta, (packed, ring).
      real(wp), allocatable :: dplm(:, :)
      !> m Pbar / sin(theta), (packed, ring).
      real(wp), allocatable :: mplm(:, :)
      !> Trigonometric rows: trig(m+1, j) = cos(m phi_j), trig(lmax+1+m, j) = sin(m phi_j), m >= 1.
      real(wp), allocatable :: trig(:, :)
   end type sh_grid_type

contains

   !> Build a grid with ntheta x nphi nodes and tables to degree lmax.
   pure function new_sh_grid(ntheta, nphi, lmax) result(grid)
      !> Number of Gauss-Legendre nodes in cos(theta).
      integer, intent(in) :: ntheta
      !> Number of azimuths.
      integer, intent(in) :: nphi
      !> Highest degree to support.
      integer, intent(in) :: lmax
      type(sh_grid_type) :: grid
      type(legendre_table_type) :: tab
      real(wp), allocatable :: p(:)
      integer :: i, j, m, k, np

      grid%sphere = new_sphere_grid(ntheta, nphi)
      grid%lmax = lmax
      np = packed_size(lmax)
      tab = new_legendre_table(lmax + 1)
      allocate (grid%idx(0:lmax + 1))
      k = 1
      do m = 0, lmax
         grid%idx(m) = k
         k = k + lmax - m + 1
      end do
      grid%idx(lmax + 1) = k
      allocate (grid%plm(np, ntheta), grid%dplm(np, ntheta), grid%mplm(np, ntheta))
      allocate (p(packed_size(lmax + 1)))
      do i = 1, ntheta
         call legendre_values(tab, grid%sphere%x(i), p, grid%sphere%sint(i))
         do m = 0, lmax
            grid%plm(grid%idx(m):grid%idx(m) + lmax - m, i) = p(tab%idx(m):tab%idx(m) + lmax - m)
         end do
         call legendre_theta_derivatives(tab, p, lmax, grid%idx, grid%dplm(:, i), grid%mplm(:, i))
      end do
      allocate (grid%trig(2 * lmax + 1, nphi))
      do j = 1, nphi
         grid%trig(1, j) = 1.0_wp
         do m = 1, lmax
            grid%trig(m + 1, j) = cos(m * grid%sphere%phi(j))
            grid%trig(lmax + 1 + m, j) = sin(m * grid%sphere%phi(j))
         end do
      end do
   end function new_sh_grid

   !> r on the grid, r(i, j) at (theta_i, phi_j); optionally dr/dtheta and (dr/dphi)/sin(theta).
   !> The expansion is truncated at nused (default: min(shape%nmax, grid%lmax)).
   pure subroutine sh_synthesize(grid, shape, r, r_theta, r_phi_sin, nused)
      !> Grid with tables.
      type(sh_grid_type), intent(in) :: grid
      !> Expansion to evaluate.
      type(sh_expansion_type), intent(in) :: shape
      !> Radii, (ntheta, nphi).
      real(wp), intent(out) :: r(:, :)
      !> dr/dtheta, (ntheta, nphi).
      real(wp), intent(out), optional :: r_theta(:, :)
      !> (dr/dphi)/sin(theta), (ntheta, nphi).
      real(wp), intent(out), optional :: r_phi_sin(:, :)
      !> Degree at which to truncate.
      integer, intent(in), optional :: nused
      integer :: l

      l = min(shape%nmax, grid%lmax)
      if (present(nused)) l = max(0, min(l, nused))
      call stage(grid%plm, .false., r)
      if (present(r_theta)) call stage(grid%dplm, .false., r_theta)
      if (present(r_phi_sin)) call stage(grid%mplm, .true., r_phi_sin)
   contains
      !> out = sum_m [ (sum_n A P) cos + (sum_n B P) sin ], or the phi-derivative form
      !> sum_m [ (sum_n B P) cos - (sum_n A P) sin ] when `dphi` (P then holds m P / sin).
      pure subroutine stage(tab, dphi, out)
         real(wp), intent(in) :: tab(:, :)
         logical, intent(in) :: dphi
         real(wp), intent(out) :: out(:, :)
         real(wp) :: g(grid%sphere%ntheta, 2 * l + 1), t(2 * l + 1, grid%sphere%nphi)
         real(wp) :: ca(grid%sphere%ntheta), cb(grid%sphere%ntheta)
         integer :: m, k0, k1, lm

         lm = grid%lmax
         do m = 0, l
            k0 = grid%idx(m)
            k1 = k0 + l - m
            ca = matmul(shape%a(m:l, m), tab(k0:k1, :))
            if (m == 0) then
               g(:, 1) = merge(0.0_wp, 1.0_wp, dphi) * ca
            else
               cb = matmul(shape%b(m:l, m), tab(k0:k1, :))
               if (dphi) then
                  g(:, m + 1) = cb
                  g(:, l + 1 + m) = -ca
               else
                  g(:, m + 1) = ca
                  g(:, l + 1 + m) = cb
               end if
            end if
            t(m + 1, :) = grid%trig(m + 1, :)
            if (m > 0) t(l + 1 + m, :) = grid%trig(lm + 1 + m, :)
         end do
         out = matmul(g, t)
      end subroutine stage
   end subroutine sh_synthesize

   !> Surface points and outward unit normals (body frame) at every grid node:
   !> x(:, i, j) = r rhat and nrm(:, i, j) ~ r rhat - r_theta thetahat - (r_phi / sin theta) phihat.
   pure subroutine sh_grid_normals(grid, shape, x, nrm, nused)
      !> Grid with tables.
      type(sh_grid_type), intent(in) :: grid
      !> Expansion.
      type(sh_expansion_type), intent(in) :: shape
      !> Surface points, (3, ntheta, nphi).
      real(wp), intent(out) :: x(:, :, :)
      !> Unit normals, (3, ntheta, nphi).
      real(wp), intent(out) :: nrm(:, :, :)
      !> Degree at which to truncate.
      integer, intent(in), optional :: nused
      real(wp), allocatable :: r(:, :), rt(:, :), rp(:, :)
      real(wp) :: st, ct, cp, sp, rh(3), th(3), ph(3), v(3)
      integer :: i, j, nt, np
      nt = grid%sphere%ntheta
      np = grid%sphere%nphi
      allocate (r(nt, np), rt(nt, np), rp(nt, np))
      call sh_synthesize(grid, shape, r, rt, rp, nused)
      do j = 1, np
         cp = cos(grid%sphere%phi(j))
         sp = sin(grid%sphere%phi(j))
         do i = 1, nt
            st = grid%sphere%sint(i)
            ct = grid%sphere%x(i)
            rh = [st * cp, st * sp, ct]
            th = [ct * cp, ct * sp, -st]
            ph = [-sp, cp, 0.0_wp]
            x(:, i, j) = r(i, j) * rh
            v = r(i, j) * rh - rt(i, j) * th - rp(i, j) * ph
            nrm(:, i, j) = v / norm2(v)
         end do
      end do
   end subroutine sh_grid_normals

   !> Project grid values f(i, j) onto real SH coefficients of degree <= nmax by Gauss quadrature
   !> (the inverse of `sh_synthesize` for band-limited f of degree <= min(nmax, grid%lmax) when the
   !> grid has ntheta > nmax and nphi > 2 nmax).
   pure subroutine sh_analyze(grid, f, nmax, a, b)
      !> Grid with tables (lmax >= nmax).
      type(sh_grid_type), intent(in) :: grid
      !> Values on the grid, (ntheta, nphi).
      real(wp), intent(in) :: f(:, :)
      !> Highest degree to compute.
      integer, intent(in) :: nmax
      !> Cosine and sine coefficients (0:nmax, 0:nmax), ready for new_sh_expansion_real.
      real(wp), intent(out) :: a(0:, 0:), b(0:, 0:)
      real(wp) :: fc(grid%sphere%ntheta, 0:nmax), fs(grid%sphere%ntheta, 0:nmax)
      real(wp) :: wfac
      integer :: i, m, n, k0

      ! azimuthal transform per ring (weights folded in)
      do i = 1, grid%sphere%ntheta
         do m = 0, nmax
            fc(i, m) = sum(f(i, :) * grid%trig(m + 1, :)) * grid%sphere%weight(i)
            if (m > 0) then
               fs(i, m) = sum(f(i, :) * grid%trig(grid%lmax + 1 + m, :)) * grid%sphere%weight(i)
            else
               fs(i, m) = 0.0_wp
            end if
         end do
      end do
      a = 0.0_wp
      b = 0.0_wp
      do m = 0, nmax
         wfac = merge(1.0_wp, 2.0_wp, m == 0)
         k0 = grid%idx(m)
         do n = m, nmax
            a(n, m) = wfac * sum(grid%plm(k0 + n - m, :) * fc(:, m))
            if (m > 0) b(n, m) = wfac * sum(grid%plm(k0 + n - m, :) * fs(:, m))
         end do
      end do
   end subroutine sh_analyze
end module anm_sh_grid
