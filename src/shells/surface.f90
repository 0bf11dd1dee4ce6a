!> Per-shape surface data for shell construction: a pointwise evaluator of r and its first and
!> second angular derivatives, a dense sample of r and its derivatives on a Gauss grid (surface
!> points and normals follow from them), syntheses and analyses on that grid, and the distance
!> from a point to the particle surface (the definition of a shell).
!>
!> The distance query uses the star shape: a surface point x within distance D of a point y
!> (|y| > D) lies in the cone of half-angle asin(D/|y|) about y, so only the grid samples in that
!> spherical cap are examined. The discrete local minima of |y - x_s| in the cap are refined by a
!> Newton minimisation of |y - x(theta, phi)|^2 on the exact expansion.
!>
!> Usage:
!>     call new_shell_surface(surf, shape, 120)
!>     call surface_distance(surf, y, tcut, d, theta_c, phi_c)   ! d > tcut means "farther"
!>     call eval_surface(surf, theta, phi, f)                     ! f = r, r_t, r_p, r_tt, r_tp, r_pp
!>     call node_geometry(surf, i, j, x, n)                       ! sample point and normal
!>     call grid_synthesis(surf%grid, a, b, l, values)            ! (a, b) of degree l on the grid
module anm_shells_surface
   use anm_core_kinds, only: wp, pi, two_pi
   use anm_sh_expansion, only: sh_expansion_type
   use anm_sh_grid, only: sh_grid_type
   use anm_sh_quadrature, only: new_sphere_grid
   use anm_sh_legendre, only: legendre_table_type, new_legendre_table, legendre_values, packed_size
   use anm_sh_kernel, only: sh_lanes, sh_sum_surface, sh_sum_surface_lanes
   implicit none
   private

   !> Points per group of `eval_surface_many` (the kernel's lane count).
   integer, parameter :: lanes = sh_lanes

   public :: shell_surface_type, new_shell_surface, eval_surface, eval_surface_many, surface_frame, &
      & surface_frame_trig, surface_distance, closest_point, cross3, grid_synthesis, grid_analysis, &
      & node_geometry, column_geometry

   !> Immutable per-shape data (safe to share between threads).
   type :: shell_surface_type
      !> Particle expansion.
      type(sh_expansion_type) :: shape
      !> Sample grid with the value tables (`plm`, `trig`) to the degree of the fit of the outer
      !> surface; the derivative tables (`dplm`, `mplm`) are not built.
      type(sh_grid_type) :: grid
      !> Radii at the samples (the surface points and outward normals at the samples follow from
      !> f and the grid: `node_geometry`, `column_geometry`).
      real(wp), allocatable :: r(:, :)
      !> r and its derivatives at the samples, f(:, i, j) as returned by `eval_surface`.
      real(wp), allocatable :: f(:, :, :)
      !> Largest distance between grid-adjacent samples (diagonals included).
      real(wp) :: hmax = 0.0_wp
      !> Largest sampled radius.
      real(wp) :: rmax = 0.0_wp
      !> Smallest sampled radius.
      real(wp) :: rmin = 0.0_wp
   end type shell_surface_type

contains

   !> Precompute the surface data of `shape` on an ntheta x 2 ntheta Gauss grid whose tables
   !> support degree lmax (>= shape%nmax).
   pure subroutine new_shell_surface(surf, shape, ntheta, lmax)
      !> Surface data to build.
      type(shell_surface_type), intent(out) :: surf
      !> Particle expansion.
      type(sh_expansion_type), intent(in) :: shape
      !> Polar nodes of the sample grid.
      integer, intent(in) :: ntheta
      !> Highest degree the grid tables must support.
      integer, intent(in) :: lmax
      real(wp), allocatable :: px(:, :), py(:, :), pz(:, :), nx(:), ny(:), nz(:), cap(:, :, :)
      integer :: j, nt, np, c, c1
      real(wp) :: h

      surf%shape = shape
      nt = ntheta
      np = 2 * ntheta
      call new_value_grid(surf%grid, nt, np, max(lmax, shape%nmax, 2))
      allocate (surf%r(nt, np), surf%f(6, nt, np))
      call grid_derivatives(surf%grid, shape, surf%f)
      ! radii and the largest distance between grid-adjacent samples (diagonals included), with
      ! the points of the current, previous and first columns
      allocate (px(nt, 3), py(nt, 3), pz(nt, 3), nx(nt), ny(nt), nz(nt), cap(3, 2, np))
      h = 0.0_wp
      c = 1
      do j = 1, np
         c = merge(1, 2 + mod(j, 2), j == 1)
         call column_geometry(surf, j, px(:, c), py(:, c), pz(:, c), nx, ny, nz)
         surf%r(:, j) = sqrt(px(:, c)**2 + py(:, c)**2 + pz(:, c)**2)
         cap(:, 1, j) = [px(1, c), py(1, c), pz(1, c)]
         cap(:, 2, j) = [px(nt, c), py(nt, c), pz(nt, c)]
         if (j > 1) then
            ! pairs of column j - 1 (buffer c1) and column j (buffer c)
            c1 = merge(1, 2 + mod(j - 1, 2), j == 2)
            call column_pairs(px(:, c1), py(:, c1), pz(:, c1), px(:, c), py(:, c), pz(:, c), h)
         end if
      end do
      ! the last column with the first
      call column_pairs(px(:, c), py(:, c), pz(:, c), px(:, 1), py(:, 1), pz(:, 1), h)
      ! the polar caps: samples of the first and last rings are joined across the pole
      do j = 1, np / 2
         h = max(h, dist2(cap(:, 1, j), cap(:, 1, j + np / 2)), dist2(cap(:, 2, j), cap(:, 2, j + np / 2)))
      end do
      h = sqrt(h)
      surf%hmax = h
      surf%rmax = maxval(surf%r)
      surf%rmin = minval(surf%r)
   contains
      !> h = max(h, squared distances between grid-adjacent samples of columns a and b, b after a).
      pure subroutine column_pairs(ax, ay, az, bx, by, bz, h)
         real(wp), intent(in) :: ax(:), ay(:), az(:), bx(:), by(:), bz(:)
         real(wp), intent(inout) :: h
         integer :: i, nt
         nt = size(ax)
         do i = 1, nt
            h = max(h, (ax(i) - bx(i))**2 + (ay(i) - by(i))**2 + (az(i) - bz(i))**2)
         end do
         do i = 1, nt - 1
            h = max(h, (ax(i) - ax(i + 1))**2 + (ay(i) - ay(i + 1))**2 + (az(i) - az(i + 1))**2, &
                    (ax(i) - bx(i + 1))**2 + (ay(i) - by(i + 1))**2 + (az(i) - bz(i + 1))**2, &
                    (bx(i) - ax(i + 1))**2 + (by(i) - ay(i + 1))**2 + (bz(i) - az(i + 1))**2)
         end do
      end subroutine column_pairs
   end subroutine new_shell_surface

   !> Surface point and outward unit normal of sample (i, j) from r and its derivatives there:
   !> x = r rhat, n ~ r rhat - r_theta thetahat - (r_phi / sin theta) phihat.
   pure subroutine node_geometry(surf, i, j, x, n)
      !> Surface data.
      type(shell_surface_type), intent(in) :: surf
      !> Node (ring, column).
      integer, intent(in) :: i, j
      !> Point and unit normal.
      real(wp), intent(out) :: x(3), n(3)
      call sample_geometry(surf%f(1, i, j), surf%f(2, i, j), surf%f(3, i, j), surf%grid%sphere%sint(i), &
                           surf%grid%sphere%x(i), surf%grid%trig(2, j), surf%grid%trig(surf%grid%lmax + 2, j), &
                           x(1), x(2), x(3), n(1), n(2), n(3))
   end subroutine node_geometry

   !> `node_geometry` for every sample of column j (components in separate arrays of the rings).
   pure subroutine column_geometry(surf, j, px, py, pz, nx, ny, nz)
      !> Surface data.
      type(shell_surface_type), intent(in) :: surf
      !> Column.
      integer, intent(in) :: j
      !> Points and unit normals of the samples of the column, (ntheta) each.
      real(wp), intent(out) :: px(:), py(:), pz(:), nx(:), ny(:), nz(:)
      real(wp) :: cp, sp
      integer :: i
      cp = surf%grid%trig(2, j)
      sp = surf%grid%trig(surf%grid%lmax + 2, j)
      do i = 1, surf%grid%sphere%ntheta
         call sample_geometry(surf%f(1, i, j), surf%f(2, i, j), surf%f(3, i, j), surf%grid%sphere%sint(i), &
                              surf%grid%sphere%x(i), cp, sp, px(i), py(i), pz(i), nx(i), ny(i), nz(i))
      end do
   end subroutine column_geometry

   !> Point and outward unit normal from r, r_theta, r_phi and the direction's sines and cosines.
   elemental subroutine sample_geometry(r, rt, rp, st, ct, cp, sp, x1, x2, x3, n1, n2, n3)
      real(wp), intent(in) :: r, rt, rp, st, ct, cp, sp
      real(wp), intent(out) :: x1, x2, x3, n1, n2, n3
      real(wp) :: rps, vx, vy, vz, vn
      rps = rp / st
      x1 = r * (st * cp)
      x2 = r * (st * sp)
      x3 = r * ct
      vx = x1 - rt * (ct * cp) + rps * sp
      vy = x2 - rt * (ct * sp) - rps * cp
      vz = x3 + rt * st
      vn = 1.0_wp / sqrt(vx * vx + vy * vy + vz * vz)
      n1 = vx * vn
      n2 = vy * vn
      n3 = vz * vn
   end subroutine sample_geometry

   !> Gauss grid of ntheta x nphi nodes with the Legendre values (`plm`) and trigonometric rows
   !> (`trig`) to degree lmax, the tables `sh_synthesize` uses for values; the derivative tables
   !> (`dplm`, `mplm`) are not built (the derivatives come from `grid_derivatives`).
   pure subroutine new_value_grid(grid, ntheta, nphi, lmax)
      type(sh_grid_type), intent(out) :: grid
      integer, intent(in) :: ntheta, nphi, lmax
      type(legendre_table_type) :: tab
      real(wp), allocatable :: ph(:)
      integer :: i, j, m, k

      grid%sphere = new_sphere_grid(ntheta, nphi)
      grid%lmax = lmax
      tab = new_legendre_table(lmax)
      ! (the packed layout of a degree-lmax table is the grid's)
      allocate (grid%idx(0:lmax + 1))
      k = 1
      do m = 0, lmax
         grid%idx(m) = k
         k = k + lmax - m + 1
      end do
      grid%idx(lmax + 1) = k
      allocate (grid%plm(packed_size(lmax), ntheta))
      do i = 1, ntheta
         call legendre_values(tab, grid%sphere%x(i), grid%plm(:, i), grid%sphere%sint(i))
      end do
      ! cos(m phi) and sin(m phi) a row at a time (the compiler vectorises the calls)
      allocate (grid%trig(2 * lmax + 1, nphi), ph(nphi))
      grid%trig(1, :) = 1.0_wp
      do m = 1, lmax
         do j = 1, nphi
            ph(j) = m * grid%sphere%phi(j)
         end do
         do j = 1, nphi
            grid%trig(m + 1, j) = cos(ph(j))
            grid%trig(lmax + 1 + m, j) = sin(ph(j))
         end do
      end do
   end subroutine new_value_grid

   !> r and its first and second angular derivatives at every node of `grid` (the layout of
   !> `eval_surface`): per ring and order m, eight Legendre sums over n (of a and b weighted by
   !> 1, n, e_{n+1,m} (shifted) and n (n + 1)) give the m-th azimuthal coefficients of r, r_theta
   !> (dPbar_nm/dtheta = (n cos Pbar_nm - e_nm Pbar_{n-1,m}) / sin), r_phi, r_thetaphi, r_phiphi and
   !> the Laplacian term sum n (n + 1) a_nm Y_nm; one product with the trigonometric rows per
   !> quantity; then the Legendre equation gives r_thetatheta = -cot r_theta - L r - r_phiphi / sin^2.
   pure subroutine grid_derivatives(grid, shape, f)
      !> Grid with value tables.
      type(sh_grid_type), intent(in) :: grid
      !> Expansion.
      type(sh_expansion_type), intent(in) :: shape
      !> f(:, i, j) = [r, r_t, r_p, r_tt, r_tp, r_pp] at node (i, j).
      real(wp), intent(out) :: f(:, :, :)
      real(wp), allocatable :: c(:, :), sums(:, :), g(:, :, :), w(:, :), lap(:, :)
      integer :: n, m, l, nt, np, i, j, k0, q
      real(wp) :: rn, rm, st, ct, at, bt, en

      l = min(shape%nmax, grid%lmax)
      nt = grid%sphere%ntheta
      np = grid%sphere%nphi
      allocate (c(8, 0:l), sums(8, nt), g(nt, 2 * l + 1, 6), w(nt, np), lap(nt, np))
      g = 0.0_wp
      do m = 0, l
         rm = real(m, wp)
         k0 = grid%idx(m)
         c = 0.0_wp
         do n = m, l
            rn = real(n, wp)
            c(1, n) = shape%a(n, m)
            c(2, n) = shape%b(n, m)
            c(3, n) = rn * shape%a(n, m)
            c(4, n) = rn * shape%b(n, m)
            if (n < l) then
               ! e_{n+1,m} = sqrt((2n+3)((n+1)^2 - m^2)/(2n+1))
               en = sqrt((2.0_wp * rn + 3.0_wp) * ((rn + 1.0_wp)**2 - rm * rm) / (2.0_wp * rn + 1.0_wp))
               c(5, n) = en * shape%a(n + 1, m)
               c(6, n) = en * shape%b(n + 1, m)
            end if
            c(7, n) = rn * (rn + 1.0_wp) * shape%a(n, m)
            c(8, n) = rn * (rn + 1.0_wp) * shape%b(n, m)
         end do
         do i = 1, nt
            sums(:, i) = 0.0_wp
            do n = m, l
               sums(:, i) = sums(:, i) + c(:, n) * grid%plm(k0 + n - m, i)
            end do
         end do
         do i = 1, nt
            st = grid%sphere%sint(i)
            ct = grid%sphere%x(i)
            at = (ct * sums(3, i) - sums(5, i)) / st
            bt = (ct * sums(4, i) - sums(6, i)) / st
            g(i, m + 1, 1) = sums(1, i)
            g(i, m + 1, 2) = at
            g(i, m + 1, 3) = rm * sums(2, i)
            g(i, m + 1, 4) = sums(7, i)
            g(i, m + 1, 5) = rm * bt
            g(i, m + 1, 6) = -rm * rm * sums(1, i)
            if (m > 0) then
               g(i, l + 1 + m, 1) = sums(2, i)
               g(i, l + 1 + m, 2) = bt
               g(i, l + 1 + m, 3) = -rm * sums(1, i)
               g(i, l + 1 + m, 4) = sums(8, i)
               g(i, l + 1 + m, 5) = -rm * at
               g(i, l + 1 + m, 6) = -rm * rm * sums(2, i)
            end if
         end do
      end do
      do q = 1, 6
         if (q == 4) then
            call azimuthal_sum(grid, g(:, :, q), l, lap)
            cycle
         end if
         call azimuthal_sum(grid, g(:, :, q), l, w)
         do j = 1, np
            do i = 1, nt
               f(q, i, j) = w(i, j)
            end do
         end do
      end do
      do j = 1, np
         do i = 1, nt
            st = grid%sphere%sint(i)
            ct = grid%sphere%x(i)
            f(4, i, j) = -ct / st * f(2, i, j) - lap(i, j) - f(6, i, j) / (st * st)
         end do
      end do
   end subroutine grid_derivatives

   !> out(i, j) = sum_m g(i, m + 1) cos(m phi_j) + sum_{m >= 1} g(i, l + 1 + m) sin(m phi_j), m <= l
   !> (the azimuthal stage of a synthesis; a column at a time, the grid's trigonometric rows).
   pure subroutine azimuthal_sum(grid, g, l, out)
      !> Grid with trigonometric rows to degree >= l.
      type(sh_grid_type), intent(in) :: grid
      !> Per ring the cosine (columns 1..l + 1) and sine (l + 2..2 l + 1) coefficients.
      real(wp), intent(in) :: g(:, :)
      !> Highest order.
      integer, intent(in) :: l
      !> Values at the nodes, (ntheta, nphi).
      real(wp), intent(out) :: out(:, :)
      integer :: j, m, lm

      lm = grid%lmax
      do j = 1, size(out, 2)
         out(:, j) = g(:, 1)
         do m = 1, l
            out(:, j) = out(:, j) + g(:, m + 1) * grid%trig(m + 1, j) + g(:, l + 1 + m) * grid%trig(lm + 1 + m, j)
         end do
      end do
   end subroutine azimuthal_sum

   !> Values on the grid of sum over n <= l of (a_nm cos m phi + b_nm sin m phi) Pbar_nm(cos theta)
   !> (b(:, 0) is not used): per ring and order the Legendre sums, then `azimuthal_sum`.
   pure subroutine grid_synthesis(grid, a, b, l, out)
      !> Grid with value tables to degree >= l.
      type(sh_grid_type), intent(in) :: grid
      !> Cosine and sine coefficients, (0:>=l, 0:>=l).
      real(wp), intent(in) :: a(0:, 0:), b(0:, 0:)
      !> Highest degree.
      integer, intent(in) :: l
      !> Values at the nodes, (ntheta, nphi).
      real(wp), intent(out) :: out(:, :)
      real(wp), allocatable :: g(:, :)
      real(wp) :: sa, sb
      integer :: i, m, n, k0

      allocate (g(grid%sphere%ntheta, 2 * l + 1))
      do m = 0, l
         k0 = grid%idx(m)
         do i = 1, grid%sphere%ntheta
            sa = 0.0_wp
            sb = 0.0_wp
            do n = m, l
               sa = sa + a(n, m) * grid%plm(k0 + n - m, i)
               sb = sb + b(n, m) * grid%plm(k0 + n - m, i)
            end do
            g(i, m + 1) = sa
            if (m > 0) g(i, l + 1 + m) = sb
         end do
      end do
      call azimuthal_sum(grid, g, l, out)
   end subroutine grid_synthesis

   !> Real SH coefficients of degree <= l of grid values f by Gauss quadrature (the inverse of
   !> `grid_synthesis` for band-limited f): per ring the azimuthal sums (a column of f at a time),
   !> then per order the Legendre sums.
   pure subroutine grid_analysis(grid, f, l, a, b)
      !> Grid with value tables to degree >= l.
      type(sh_grid_type), intent(in) :: grid
      !> Values at the nodes, (ntheta, nphi).
      real(wp), intent(in) :: f(:, :)
      !> Highest degree.
      integer, intent(in) :: l
      !> Cosine and sine coefficients (0:l, 0:l), zero outside n >= m (and b(:, 0)).
      real(wp), intent(out) :: a(0:, 0:), b(0:, 0:)
      real(wp), allocatable :: fc(:, :), fs(:, :)
      real(wp) :: wf
      integer :: i, j, m, k0, lm, nt

      lm = grid%lmax
      nt = grid%sphere%ntheta
      allocate (fc(nt, 0:l), fs(nt, 0:l))
      fc = 0.0_wp
      fs = 0.0_wp
      do j = 1, size(f, 2)
         fc(:, 0) = fc(:, 0) + f(:, j)
         do m = 1, l
            fc(:, m) = fc(:, m) + f(:, j) * grid%trig(m + 1, j)
            fs(:, m) = fs(:, m) + f(:, j) * grid%trig(lm + 1 + m, j)
         end do
      end do
      a = 0.0_wp
      b = 0.0_wp
      do m = 0, l
         k0 = grid%idx(m)
         wf = merge(1.0_wp, 2.0_wp, m == 0)
         do i = 1, nt
            a(m:l, m) = a(m:l, m) + (wf * grid%sphere%weight(i) * fc(i, m)) * grid%plm(k0:k0 + l - m, i)
            if (m > 0) b(m:l, m) = b(m:l, m) + (wf * grid%sphere%weight(i) * fs(i, m)) * grid%plm(k0:k0 + l - m, i)
         end do
      end do
   end subroutine grid_analysis

   !> Squared distance between two points.
   pure function dist2(a, b) result(d)
      real(wp), intent(in) :: a(3), b(3)
      real(wp) :: d
      d = (a(1) - b(1))**2 + (a(2) - b(2))**2 + (a(3) - b(3))**2
   end function dist2

   !> r and its derivatives at (theta, phi): f = [r, r_t, r_p, r_tt, r_tp, r_pp] (t = theta,
   !> p = phi, plain derivatives). sin(theta) may be negative (theta outside [0, pi]), which
   !> continues the expansion consistently; |sin(theta)| must not be tiny (derivatives divide by it).
   pure subroutine eval_surface(surf, theta, phi, f)
      !> Surface data.
      type(shell_surface_type), intent(in) :: surf
      !> Polar angle and azimuth.
      real(wp), intent(in) :: theta, phi
      !> r, dr/dt, dr/dp, d2r/dt2, d2r/dtdp, d2r/dp2.
      real(wp), intent(out) :: f(6)
      call sh_sum_surface(surf%shape%table, surf%shape%a, surf%shape%b, surf%shape%table%enm, surf%shape%nmax, &
         & cos(theta), sin(theta), cos(phi), sin(phi), f)
   end subroutine eval_surface

   !> `eval_surface` at many points at once, f(:, k) at (theta(k), phi(k)): the same recurrences
   !> on groups of `lanes` points held in fixed-size arrays (one vector register per quantity).
   pure subroutine eval_surface_many(surf, theta, phi, f, sc)
      !> Surface data.
      type(shell_surface_type), intent(in) :: surf
      !> Polar angles and azimuths (|sin(theta)| not tiny).
      real(wp), intent(in) :: theta(:), phi(:)
      !> f(k, :) = r, dr/dt, dr/dp, d2r/dt2, d2r/dtdp, d2r/dp2 at point k.
      real(wp), intent(out) :: f(:, :)
      !> sc(k, :) = sin(theta), cos(theta), sin(phi), cos(phi) at point k (for `surface_frame_trig`).
      real(wp), intent(out), optional :: sc(:, :)
      real(wp) :: th(lanes), ph(lanes), fl(lanes, 6), scl(lanes, 4)
      integer :: k0, nk

      do k0 = 1, size(theta), lanes
         nk = min(lanes, size(theta) - k0 + 1)
         ! a short last group is padded with the equator (any point with sin(theta) away from 0)
         th = 0.5_wp * pi
         ph = 0.0_wp
         th(1:nk) = theta(k0:k0 + nk - 1)
         ph(1:nk) = phi(k0:k0 + nk - 1)
         call eval_lanes(surf, th, ph, fl, scl)
         f(k0:k0 + nk - 1, :) = fl(1:nk, :)
         if (present(sc)) sc(k0:k0 + nk - 1, :) = scl(1:nk, :)
      end do
   end subroutine eval_surface_many

   !> `eval_surface` at `lanes` points (the kernel of `eval_surface_many`, `sh_sum_surface_lanes`).
   pure subroutine eval_lanes(surf, theta, phi, f, sc)
      type(shell_surface_type), intent(in) :: surf
      real(wp), intent(in) :: theta(lanes), phi(lanes)
      real(wp), intent(out) :: f(lanes, 6), sc(lanes, 4)
      real(wp), dimension(lanes) :: x, s, cp, sp

      x = cos(theta)
      s = sin(theta)
      cp = cos(phi)
      sp = sin(phi)
      sc(:, 1) = s
      sc(:, 2) = x
      sc(:, 3) = sp
      sc(:, 4) = cp
      call sh_sum_surface_lanes(surf%shape%table, surf%shape%a, surf%shape%b, surf%shape%table%enm, surf%shape%nmax, &
         & x, s, cp, sp, f)
   end subroutine eval_lanes

   !> Surface point, tangents and second derivatives at (theta, phi) from f of `eval_surface`:
   !> x, x_t, x_p, x_tt, x_tp, x_pp (Cartesian, body frame).
   pure subroutine surface_frame(theta, phi, f, x, xt, xp, xtt, xtp, xpp)
      !> Direction.
      real(wp), intent(in) :: theta, phi
      !> r and derivatives from eval_surface.
      real(wp), intent(in) :: f(6)
      !> Point, first and second derivatives.
      real(wp), intent(out) :: x(3), xt(3), xp(3), xtt(3), xtp(3), xpp(3)
      call surface_frame_trig([sin(theta), cos(theta), sin(phi), cos(phi)], f, x, xt, xp, xtt, xtp, xpp)
   end subroutine surface_frame

   !> `surface_frame` from the sines and cosines of the direction, sc = [sin theta, cos theta,
   !> sin phi, cos phi] (as returned by `eval_surface_many`), without trigonometric calls.
   pure subroutine surface_frame_trig(sc, f, x, xt, xp, xtt, xtp, xpp)
      !> sin(theta), cos(theta), sin(phi), cos(phi).
      real(wp), intent(in) :: sc(4)
      !> r and derivatives from eval_surface.
      real(wp), intent(in) :: f(6)
      !> Point, first and second derivatives.
      real(wp), intent(out) :: x(3), xt(3), xp(3), xtt(3), xtp(3), xpp(3)
      real(wp) :: st, ct, sp, cp, rh(3), th(3), ph(3), rho(3)
      st = sc(1)
      ct = sc(2)
      sp = sc(3)
      cp = sc(4)
      rh = [st * cp, st * sp, ct]
      th = [ct * cp, ct * sp, -st]
      ph = [-sp, cp, 0.0_wp]
      rho = [cp, sp, 0.0_wp]   ! = st rh + ct th
      x = f(1) * rh
      xt = f(2) * rh + f(1) * th
      xp = f(3) * rh + f(1) * st * ph
      xtt = (f(4) - f(1)) * rh + 2.0_wp * f(2) * th
      xtp = f(5) * rh + f(3) * th + (f(2) * st + f(1) * ct) * ph
      xpp = f(6) * rh + 2.0_wp * f(3) * st * ph - f(1) * st * rho
   end subroutine surface_frame_trig

   !> Cross product.
   pure function cross3(a, b) result(c)
      !> Vectors.
      real(wp), intent(in) :: a(3), b(3)
      real(wp) :: c(3)
      c = cross(a, b)
   end function cross3

   include "anm_cross.inc"

   !> Local minimisation of |y - x(theta, phi)| by Newton's method (Gauss-Newton with step
   !> halving where the Hessian is not positive definite), from (theta, phi).
   pure subroutine closest_point(surf, y, theta, phi, dist)
      !> Surface data.
      type(shell_surface_type), intent(in) :: surf
      !> Point.
      real(wp), intent(in) :: y(3)
      !> Start on input, local minimiser on output.
      real(wp), intent(inout) :: theta, phi
      !> Distance |y - x(theta, phi)| at the minimiser.
      real(wp), intent(out) :: dist
      real(wp) :: f(6), x(3), xt(3), xp(3), xtt(3), xtp(3), xpp(3), d(3)
      real(wp) :: h11, h12, h22, g1, g2, det, dt, dp, fval, fnew, tn, pn, lam
      integer :: it, k
      logical :: newton

      call eval_surface(surf, theta, phi, f)
      call surface_frame(theta, phi, f, x, xt, xp, xtt, xtp, xpp)
      d = y - x
      fval = dot_product(d, d)
      do it = 1, 40
         g1 = -dot_product(d, xt)
         g2 = -dot_product(d, xp)
         h11 = dot_product(xt, xt) - dot_product(d, xtt)
         h12 = dot_product(xt, xp) - dot_product(d, xtp)
         h22 = dot_product(xp, xp) - dot_product(d, xpp)
         det = h11 * h22 - h12 * h12
         newton = h11 > 0.0_wp .and. det > 1.0e-12_wp * h11 * max(h22, tiny(h22))
         if (.not. newton) then
            h11 = dot_product(xt, xt)
            h12 = dot_product(xt, xp)
            h22 = dot_product(xp, xp) + 1.0e-12_wp * h11
            det = h11 * h22 - h12 * h12
         end if
         dt = -(h22 * g1 - h12 * g2) / det
         dp = -(h11 * g2 - h12 * g1) / det
         lam = min(1.0_wp, 0.3_wp / max(abs(dt), abs(dp), tiny(dt)))
         do k = 1, 30
            tn = theta + lam * dt
            pn = phi + lam * dp
            call eval_surface(surf, tn, pn, f)
            call surface_frame(tn, pn, f, x, xt, xp, xtt, xtp, xpp)
            d = y - x
            fnew = dot_product(d, d)
            if (fnew <= fval) exit
            lam = 0.5_wp * lam
         end do
         if (fnew > fval) then
            ! no decrease possible at rounding level: converged
            call eval_surface(surf, theta, phi, f)
            call surface_frame(theta, phi, f, x, xt, xp, xtt, xtp, xpp)
            d = y - x
            exit
         end if
         theta = tn
         phi = pn
         fval = fnew
         if (lam * max(abs(dt), abs(dp)) < 1.0e-13_wp) exit
      end do
      dist = norm2(d)
   end subroutine closest_point

   !> Distance from y to the particle surface if it is below tcut: examines the samples in the
   !> cone about y that can lie within tcut + hmax of y, refines every discrete local minimum of
   !> the sample distance and returns the smallest. Returns dist = huge when no sample is within
   !> tcut + hmax (then the true distance exceeds tcut). (theta_c, phi_c) is the closest point.
   pure subroutine surface_distance(surf, y, tcut, dist, theta_c, phi_c, known)
      !> Surface data.
      type(shell_surface_type), intent(in) :: surf
      !> Point (body frame), outside the particle.
      real(wp), intent(in) :: y(3)
      !> Distances above tcut need not be resolved.
      real(wp), intent(in) :: tcut
      !> Distance to the surface (or huge).
      real(wp), intent(out) :: dist
      !> Closest point's direction.
      real(wp), intent(out) :: theta_c, phi_c
      !> A known local minimiser of the distance (surface point): local minima of the samples
      !> within 1.5 hmax of it are its own basin and are not refined (their sample distance counts).
      real(wp), intent(in), optional :: known(3)
      real(wp), allocatable :: w(:, :)
      integer, allocatable :: jidx(:)
      real(wp) :: ry, ty, py, reach, alpha, dphi, dth, width, dmin, th, ph, dloc, wc, xs(3), ns(3)
      integer :: nt, np, i0, i1, ncol, i, jj, j, a, b, ia, jb, j0
      logical :: all_phi, is_min

      nt = surf%grid%sphere%ntheta
      np = surf%grid%sphere%nphi
      dist = huge(1.0_wp)
      theta_c = 0.0_wp
      phi_c = 0.0_wp
      ry = norm2(y)
      reach = tcut + surf%hmax
      dth = pi / nt * 2.0_wp
      dphi = two_pi / np
      if (reach >= 0.999_wp * ry) then
         alpha = pi
      else
         alpha = asin(reach / ry)
      end if
      ty = acos(max(-1.0_wp, min(1.0_wp, y(3) / ry)))
      py = atan2(y(2), y(1))
      if (py < 0.0_wp) py = py + two_pi
      i0 = nt + 1
      i1 = 0
      do i = 1, nt
         if (abs(surf%grid%sphere%theta(i) - ty) <= alpha + dth) then
            i0 = min(i0, i)
            i1 = max(i1, i)
         end if
      end do
      if (i1 < i0) return
      all_phi = ty - alpha - dth <= 0.0_wp .or. ty + alpha + dth >= pi
      if (.not. all_phi) then
         width = asin(min(1.0_wp, sin(alpha) / sin(ty))) + 2.0_wp * dphi
         all_phi = width >= pi .or. sin(alpha) >= sin(ty)
      end if
      if (all_phi) then
         ncol = np
         j0 = 1
         if (i0 == 1) i0 = 1
      else
         j0 = floor((py - width) / dphi) + 1
         ncol = floor((py + width) / dphi) + 2 - j0
      end if
      allocate (w(i0:i1, ncol), jidx(ncol))
      do jj = 1, ncol
         jidx(jj) = 1 + modulo(j0 - 1 + jj - 1, np)
         j = jidx(jj)
         do i = i0, i1
            call node_geometry(surf, i, j, xs, ns)
            w(i, jj) = norm2(y - xs)
         end do
      end do
      dmin = huge(1.0_wp)
      do jj = 1, ncol
         do i = i0, i1
            wc = w(i, jj)
            if (wc >= reach) cycle
            is_min = .true.
            do b = -1, 1
               jb = jj + b
               if (all_phi) then
                  jb = 1 + modulo(jb - 1, ncol)
               else if (jb < 1 .or. jb > ncol) then
                  cycle
               end if
               do a = -1, 1
                  ia = i + a
                  if (ia < i0 .or. ia > i1) cycle
                  if (w(ia, jb) < wc) is_min = .false.
               end do
            end do
            if (.not. is_min) cycle
            th = surf%grid%sphere%theta(i)
            ph = surf%grid%sphere%phi(jidx(jj))
            if (present(known)) then
               call node_geometry(surf, i, jidx(jj), xs, ns)
               if (norm2(xs - known) < 1.5_wp * surf%hmax) then
                  if (wc < dmin) then
                     dmin = wc
                     theta_c = th
                     phi_c = ph
                  end if
                  cycle
               end if
            end if
            call closest_point(surf, y, th, ph, dloc)
            if (dloc < dmin) then
               dmin = dloc
               theta_c = th
               phi_c = ph
            end if
         end do
      end do
      dist = dmin
   end subroutine surface_distance
end module anm_shells_surface
