!> Tests of the SH numerics against outside truth: Gauss-Legendre moments and the 3-point rule,
!> Legendre values from 200-digit references (mpmath and the explicit polynomial agree),
!> Unsold's theorem sum_m |Y_n^m|^2 = (2n+1)/(4 pi) to degree 200, orthonormality by quadrature,
!> closed-form Y_1^1, Y_2^2 (the Condon-Shortley convention of the files), derivatives against
!> finite differences, grid synthesis against point evaluation, analysis round trips, normals,
!> the surface gradient and the Hessian bound against finite differences along great circles.
module test_sh
   use anm_core_kinds, only: wp, pi, i8
   use anm_core_error, only: error_type
   use anm_core_random, only: rng_type, new_rng
   use anm_sh_quadrature, only: gauss_legendre
   use anm_sh_legendre, only: legendre_table_type, new_legendre_table, legendre_values, &
      & legendre_theta_derivatives, packed_size
   use anm_sh_expansion, only: sh_expansion_type, new_sh_expansion, new_sh_expansion_real, sh_truncate, &
      & sh_to_complex, surface_normal
   use anm_sh_grid, only: sh_grid_type, new_sh_grid, sh_synthesize, sh_analyze, sh_grid_normals
   use anm_shapes_analytic, only: ellipsoid_shape
   use anm_testing, only: unittest_type, new_unittest, check
   implicit none
   private
   public :: collect_sh, random_expansion

contains

   !> Tests of this suite.
   subroutine collect_sh(tests)
      type(unittest_type), allocatable, intent(out) :: tests(:)
      tests = [ &
              new_unittest("Gauss-Legendre 3-point rule", test_gl3), &
              new_unittest("Gauss-Legendre 120-point moments", test_gl_moments), &
              new_unittest("Legendre values vs 200-digit references", test_legendre_reference), &
              new_unittest("Unsold sum rule to degree 200", test_unsold), &
              new_unittest("no overflow/underflow near the poles at degree 300", test_legendre_poles), &
              new_unittest("orthonormality by quadrature at degree 60", test_orthonormal), &
              new_unittest("closed forms Y10, Y11, Y22 (Condon-Shortley)", test_closed_forms), &
              new_unittest("theta derivatives vs finite differences", test_derivatives), &
              new_unittest("grid synthesis equals point evaluation", test_grid_vs_point), &
              new_unittest("analysis inverts synthesis", test_round_trip), &
              new_unittest("truncation keeps low degrees", test_truncation), &
              new_unittest("complex coefficients round trip", test_complex_round_trip), &
              new_unittest("surface normal vs cross product of tangents", test_normal), &
              new_unittest("grid normals of an ellipsoid are exact", test_grid_normals), &
              new_unittest("surface gradient and Hessian bound vs finite differences", test_gradient)]
   end subroutine collect_sh

   !> A random real expansion of degree nmax with mean radius 1 and decaying coefficients.
   subroutine random_expansion(nmax, seed, shape)
      integer, intent(in) :: nmax
      integer(i8), intent(in) :: seed
      type(sh_expansion_type), intent(out) :: shape
      type(rng_type) :: rng
      real(wp) :: a(0:nmax, 0:nmax), b(0:nmax, 0:nmax)
      integer :: n, m
      call new_rng(rng, seed, 99_i8)
      a = 0.0_wp
      b = 0.0_wp
      do n = 1, nmax
         do m = 0, n
            a(n, m) = 0.3_wp * rng%normal() / n**2
            if (m > 0) b(n, m) = 0.3_wp * rng%normal() / n**2
         end do
      end do
      a(0, 0) = 2.0_wp * sqrt(pi)
      call new_sh_expansion_real(shape, a, b)
   end subroutine random_expansion

   subroutine test_gl3(error)
      type(error_type), allocatable, intent(out) :: error
      real(wp), allocatable :: x(:), w(:)
      call gauss_legendre(3, x, w)
      call check(error, x(1), sqrt(0.6_wp), "node", thr=1.0e-15_wp)
      if (allocated(error)) return
      call check(error, x(2), 0.0_wp, "middle node", thr=1.0e-15_wp)
      if (allocated(error)) return
      call check(error, w(1), 5.0_wp / 9.0_wp, "weight", thr=1.0e-15_wp)
      if (allocated(error)) return
      call check(error, w(2), 8.0_wp / 9.0_wp, "middle weight", thr=1.0e-15_wp)
   end subroutine test_gl3

   subroutine test_gl_moments(error)
      type(error_type), allocatable, intent(out) :: error
      real(wp), allocatable :: x(:), w(:)
      integer :: k
      call gauss_legendre(120, x, w)
      ! exact for x^k, k <= 239: int_{-1}^{1} x^k = 2/(k+1) for even k, 0 for odd k
      do k = 0, 238, 2
         call check(error, sum(w * x**k), 2.0_wp / (k + 1), "moment", rel=1.0e-12_wp)
         if (allocated(error)) return
         call check(error, sum(w * x**(k + 1)), 0.0_wp, "odd moment", thr=1.0e-14_wp)
         if (allocated(error)) return
      end do
   end subroutine test_gl_moments

   subroutine test_legendre_reference(error)
      type(error_type), allocatable, intent(out) :: error
      integer, parameter :: nc = 11
      integer, parameter :: cn(nc) = [60, 60, 60, 60, 75, 100, 60, 30, 120, 150, 200]
      integer, parameter :: cm(nc) = [0, 1, 30, 60, 40, 7, 59, 15, 60, 150, 3]
      real(wp), parameter :: cx(nc) = [0.3_wp, -0.77_wp, 0.5_wp, 0.1_wp, 0.95_wp, 0.9999_wp, -0.999_wp, &
                                       0.123456789_wp, 0.001_wp, 0.9_wp, -0.2_wp]
      ! fully normalised, Condon-Shortley; 200-digit values (mpmath.legenp and the explicit
      ! polynomial (-1)^m (1-x^2)^(m/2) d^m P_n/dx^m agree)
      real(wp), parameter :: ref(nc) = [0.2982344431836478612893_wp, -0.09654006334672726320309_wp, &
                                        0.1260324112272724647753_wp, 0.6188222570042922439826_wp, &
                                        2.839720184305844573895e-7_wp, -0.0000678008286143314066447_wp, &
                                        2.165926052957650378766e-79_wp, -0.04907506677441338857313_wp, &
                                        0.3399427665825140886118_wp, 8.46656308356554878595e-55_wp, &
                                        0.1464748118620365440619_wp]
      type(legendre_table_type) :: tab
      real(wp), allocatable :: p(:)
      integer :: i
      real(wp) :: v, worst
      tab = new_legendre_table(200)
      allocate (p(packed_size(200)))
      worst = 0.0_wp
      do i = 1, nc
         call legendre_values(tab, cx(i), p)
         v = p(tab%idx(cm(i)) + cn(i) - cm(i))
         worst = max(worst, abs(v - ref(i)) / abs(ref(i)))
         call check(error, v, ref(i), "Pbar(n="//itoa(cn(i))//", m="//itoa(cm(i))//")", rel=1.0e-12_wp)
         if (allocated(error)) return
      end do
      print '(a,es9.2)', "        worst relative error of Legendre values: ", worst
   end subroutine test_legendre_reference

   pure function itoa(i) result(s)
      integer, intent(in) :: i
      character(len=:), allocatable :: s
      character(len=12) :: b
      write (b, '(i0)') i
      s = trim(b)
   end function itoa

   subroutine test_unsold(error)
      type(error_type), allocatable, intent(out) :: error
      type(legendre_table_type) :: tab
      real(wp), allocatable :: p(:)
      real(wp) :: x, s
      integer :: i, n, m
      tab = new_legendre_table(200)
      allocate (p(packed_size(200)))
      do i = 0, 20
         x = cos(pi * i / 20.0_wp + 1.0e-3_wp)
         call legendre_values(tab, x, p)
         do n = 0, 200, 10
            s = p(tab%idx(0) + n)**2
            do m = 1, n
               s = s + 2.0_wp * p(tab%idx(m) + n - m)**2
            end do
            call check(error, s, (2 * n + 1) / (4.0_wp * pi), "Unsold n="//itoa(n), rel=1.0e-12_wp)
            if (allocated(error)) return
         end do
      end do
   end subroutine test_unsold

   subroutine test_legendre_poles(error)
      type(error_type), allocatable, intent(out) :: error
      type(legendre_table_type) :: tab
      real(wp), allocatable :: p(:)
      real(wp) :: th(4), s
      integer :: i, n, m
      th = [1.0e-8_wp, 1.0e-3_wp, pi - 1.0e-6_wp, 0.5_wp]
      tab = new_legendre_table(300)
      allocate (p(packed_size(300)))
      do i = 1, size(th)
         call legendre_values(tab, cos(th(i)), p, sin(th(i)))
         call check(error, all(abs(p) <= huge(1.0_wp)) .and. all(p == p), "finite values")
         if (allocated(error)) return
         ! sum rule at the highest degree (all m) holds even where most terms underflow
         n = 300
         s = p(tab%idx(0) + n)**2
         do m = 1, n
            s = s + 2.0_wp * p(tab%idx(m) + n - m)**2
         end do
         call check(error, s, (2 * n + 1) / (4.0_wp * pi), "Unsold near pole", rel=1.0e-11_wp)
         if (allocated(error)) return
      end do
   end subroutine test_legendre_poles

   subroutine test_orthonormal(error)
      type(error_type), allocatable, intent(out) :: error
      type(sh_grid_type) :: grid
      integer :: n1, n2, m
      real(wp) :: s, worst
      grid = new_sh_grid(61, 122, 60)
      worst = 0.0_wp
      do m = 0, 60, 6
         do n1 = m, 60
            do n2 = m, 60, 7
               ! int Pbar_n1^m Pbar_n2^m dOmega = delta(n1, n2) (|Y_n^m|^2 integrates to 1);
               ! the grid weights carry 2 pi / nphi each, so multiply by nphi
               s = grid%sphere%nphi * sum(grid%sphere%weight * grid%plm(grid%idx(m) + n1 - m, :) &
                                          * grid%plm(grid%idx(m) + n2 - m, :))
               if (n1 == n2) s = s - 1.0_wp
               worst = max(worst, abs(s))
            end do
         end do
      end do
      call check(error, worst, 0.0_wp, "orthonormality defect", thr=1.0e-12_wp)
   end subroutine test_orthonormal

   subroutine test_closed_forms(error)
      type(error_type), allocatable, intent(out) :: error
      ! r = a00 Y00 + a10 Y10 + a11 Y11 + a1-1 Y1-1 + a22 Y22 + a2-2 Y2-2 with conjugate symmetry;
      ! Y10 = sqrt(3/4pi) cos t, Y11 = -sqrt(3/8pi) sin t e^{i p}, Y22 = sqrt(15/32pi) sin^2 t e^{2ip}
      complex(wp) :: c(0:2, -2:2), a11, a22
      type(sh_expansion_type) :: s
      real(wp) :: t, p, expected
      integer :: k
      a11 = (0.3_wp, -0.2_wp)
      a22 = (-0.15_wp, 0.4_wp)
      c = (0.0_wp, 0.0_wp)
      c(0, 0) = (5.0_wp, 0.0_wp)
      c(1, 0) = (0.7_wp, 0.0_wp)
      c(1, 1) = a11
      c(1, -1) = -conjg(a11)
      c(2, 2) = a22
      c(2, -2) = conjg(a22)
      call new_sh_expansion(s, c, 2)
      do k = 1, 25
         t = 0.13_wp * k
         p = 0.71_wp * k
         expected = 5.0_wp / sqrt(4 * pi) + 0.7_wp * sqrt(3 / (4 * pi)) * cos(t) &
                    + 2 * real(a11 * (-sqrt(3 / (8 * pi)) * sin(t) * exp((0.0_wp, 1.0_wp) * p)), wp) &
                    + 2 * real(a22 * (sqrt(15 / (32 * pi)) * sin(t)**2 * exp((0.0_wp, 2.0_wp) * p)), wp)
         call check(error, s%radius(t, p), expected, "r(theta, phi)", rel=1.0e-14_wp)
         if (allocated(error)) return
         call check(error, s%radius_dir([sin(t) * cos(p), sin(t) * sin(p), cos(t)]), expected, &
                    "r(direction)", rel=1.0e-14_wp)
         if (allocated(error)) return
      end do
   end subroutine test_closed_forms

   subroutine test_derivatives(error)
      type(error_type), allocatable, intent(out) :: error
      type(sh_expansion_type) :: s
      real(wp) :: t, p, r, rt, rps, h, fd_t, fd_p
      integer :: k
      call random_expansion(20, 3_i8, s)
      h = 1.0e-5_wp
      do k = 1, 30
         t = 0.1_wp + 0.1_wp * k
         p = 0.37_wp * k
         call s%point(t, p, r, rt, rps)
         fd_t = (s%radius(t + h, p) - s%radius(t - h, p)) / (2 * h)
         fd_p = (s%radius(t, p + h) - s%radius(t, p - h)) / (2 * h) / sin(t)
         call check(error, r, s%radius(t, p), "r", rel=1.0e-13_wp)
         if (allocated(error)) return
         call check(error, rt, fd_t, "dr/dtheta", thr=1.0e-8_wp)
         if (allocated(error)) return
         call check(error, rps, fd_p, "dr/dphi / sin", thr=1.0e-8_wp)
         if (allocated(error)) return
      end do
      ! at the pole the phi term stays finite and equals the limit
      call s%point(0.0_wp, 0.3_wp, r, rt, rps)
      call check(error, abs(rps) < 10.0_wp .and. rps == rps, "finite at the pole")
   end subroutine test_derivatives

   subroutine test_grid_vs_point(error)
      type(error_type), allocatable, intent(out) :: error
      type(sh_expansion_type) :: s
      type(sh_grid_type) :: grid
      real(wp), allocatable :: r(:, :), rt(:, :), rp(:, :)
      real(wp) :: rr, rtt, rps, worst
      integer :: i, j
      call random_expansion(30, 5_i8, s)
      grid = new_sh_grid(40, 80, 30)
      allocate (r(40, 80), rt(40, 80), rp(40, 80))
      call sh_synthesize(grid, s, r, rt, rp)
      worst = 0.0_wp
      do j = 1, 80, 3
         do i = 1, 40
            call s%point(grid%sphere%theta(i), grid%sphere%phi(j), rr, rtt, rps)
            worst = max(worst, abs(rr - r(i, j)), abs(rtt - rt(i, j)), abs(rps - rp(i, j)))
         end do
      end do
      call check(error, worst, 0.0_wp, "grid vs point", thr=1.0e-12_wp)
   end subroutine test_grid_vs_point

   subroutine test_round_trip(error)
      type(error_type), allocatable, intent(out) :: error
      type(sh_expansion_type) :: s
      type(sh_grid_type) :: grid
      real(wp), allocatable :: r(:, :), a(:, :), b(:, :)
      call random_expansion(30, 7_i8, s)
      grid = new_sh_grid(31, 62, 30)
      allocate (r(31, 62), a(0:30, 0:30), b(0:30, 0:30))
      call sh_synthesize(grid, s, r)
      call sh_analyze(grid, r, 30, a, b)
      call check(error, maxval(abs(a - s%a)) + maxval(abs(b - s%b)), 0.0_wp, "coefficients", thr=1.0e-13_wp)
   end subroutine test_round_trip

   subroutine test_truncation(error)
      type(error_type), allocatable, intent(out) :: error
      type(sh_expansion_type) :: s, t
      type(sh_grid_type) :: grid
      real(wp), allocatable :: r1(:, :), r2(:, :)
      call random_expansion(30, 9_i8, s)
      t = sh_truncate(s, 5)
      call check(error, t%nmax, 5, "degree")
      if (allocated(error)) return
      grid = new_sh_grid(32, 64, 30)
      allocate (r1(32, 64), r2(32, 64))
      call sh_synthesize(grid, s, r1, nused=5)
      call sh_synthesize(grid, t, r2)
      call check(error, maxval(abs(r1 - r2)), 0.0_wp, "nused vs truncated copy", thr=1.0e-14_wp)
   end subroutine test_truncation

   subroutine test_complex_round_trip(error)
      type(error_type), allocatable, intent(out) :: error
      type(sh_expansion_type) :: s, s2
      complex(wp), allocatable :: c(:, :)
      call random_expansion(12, 11_i8, s)
      c = sh_to_complex(s)
      call new_sh_expansion(s2, c, 12)
      call check(error, maxval(abs(s2%a - s%a)) + maxval(abs(s2%b - s%b)), 0.0_wp, "A, B", thr=1.0e-15_wp)
      if (allocated(error)) return
      call check(error, s2%radius(1.0_wp, 2.0_wp), s%radius(1.0_wp, 2.0_wp), "r", rel=1.0e-14_wp)
   end subroutine test_complex_round_trip

   subroutine test_normal(error)
      type(error_type), allocatable, intent(out) :: error
      type(sh_expansion_type) :: s
      real(wp) :: t, p, r, rt, rps, h, xt(3), xp(3), nrm(3), ref(3)
      integer :: k
      call random_expansion(10, 13_i8, s)
      h = 1.0e-6_wp
      do k = 1, 20
         t = 0.15_wp * k
         p = 0.9_wp * k
         call s%point(t, p, r, rt, rps)
         nrm = surface_normal(t, p, r, rt, rps)
         xt = (pos(t + h, p) - pos(t - h, p)) / (2 * h)
         xp = (pos(t, p + h) - pos(t, p - h)) / (2 * h)
         ref = [xt(2) * xp(3) - xt(3) * xp(2), xt(3) * xp(1) - xt(1) * xp(3), xt(1) * xp(2) - xt(2) * xp(1)]
         ref = ref / norm2(ref)
         call check(error, norm2(nrm - ref), 0.0_wp, "normal", thr=1.0e-7_wp)
         if (allocated(error)) return
         ! outward: positive component along the radial direction
         call check(error, dot_product(nrm, pos(t, p)) > 0.0_wp, "outward")
         if (allocated(error)) return
      end do
   contains
      function pos(tt, pp) result(x)
         real(wp), intent(in) :: tt, pp
         real(wp) :: x(3)
         x = s%radius(tt, pp) * [sin(tt) * cos(pp), sin(tt) * sin(pp), cos(tt)]
      end function pos
   end subroutine test_normal
   subroutine test_grid_normals(error)
      type(error_type), allocatable, intent(out) :: error
      ! the normal of x^2/a^2 + y^2/b^2 + z^2/c^2 = 1 is proportional to (x/a^2, y/b^2, z/c^2)
      type(sh_grid_type) :: grid
      real(wp) :: x(3, 40, 80), nrm(3, 40, 80), ref(3), worst
      integer :: i, j
      grid = new_sh_grid(40, 80, 40)
      call sh_grid_normals(grid, ellipsoid_shape(1.5_wp, 1.2_wp, 1.0_wp, 40), x, nrm)
      worst = 0.0_wp
      do j = 1, 80
         do i = 1, 40
            ref = x(:, i, j) / [1.5_wp**2, 1.2_wp**2, 1.0_wp]
            ref = ref / norm2(ref)
            worst = max(worst, norm2(nrm(:, i, j) - ref))
         end do
      end do
      print '(a,es9.2)', "        worst normal error on the ellipsoid grid: ", worst
      call check(error, worst, 0.0_wp, "normal", thr=1.0e-6_wp)
   end subroutine test_grid_normals

   !> radius_gradient and radius_hessian: r as radius_dir gives it; the gradient's component along
   !> every tangent direction w equals the derivative of r along the great circle through u in
   !> direction w (central differences); the Hessian bound holds the second derivative along it.
   subroutine test_gradient(error)
      type(error_type), allocatable, intent(out) :: error
      type(sh_expansion_type) :: s
      type(rng_type) :: rng
      real(wp) :: u(3), w(3), r, g(3), r2, g2(3), hm, h, d1, d2, worst1, worst2, worsth
      integer :: k
      call random_expansion(14, 17_i8, s)
      call new_rng(rng, 31_i8, 2_i8)
      h = 1.0e-4_wp
      worst1 = 0.0_wp
      worst2 = 0.0_wp
      worsth = 0.0_wp
      do k = 1, 200
         u = [rng%normal(), rng%normal(), rng%normal()]
         u = u / norm2(u)
         w = [rng%normal(), rng%normal(), rng%normal()]
         w = w - dot_product(w, u) * u
         w = w / norm2(w)
         call s%radius_gradient(u, r, g)
         call s%radius_hessian(u, r2, g2, hm)
         worst1 = max(worst1, abs(r - s%radius_dir(u)), abs(r2 - r), norm2(g2 - g), abs(dot_product(g, u)))
         d1 = (s%radius_dir(arc(h)) - s%radius_dir(arc(-h))) / (2 * h)
         d2 = (s%radius_dir(arc(h)) - 2 * s%radius_dir(u) + s%radius_dir(arc(-h))) / h**2
         worst2 = max(worst2, abs(d1 - dot_product(g, w)) / (1.0_wp + abs(d1)))
         worsth = max(worsth, abs(d2) - hm)
      end do
      print '(a,3es10.2)', "        r and gradients agree to, FD gradient error, largest |d2r/ds2| - bound: ", worst1, &
         worst2, worsth
      call check(error, worst1, 0.0_wp, "r and gradient of the two evaluations", thr=1.0e-10_wp)
      if (allocated(error)) return
      call check(error, worst2, 0.0_wp, "gradient against finite differences", thr=1.0e-6_wp)
      if (allocated(error)) return
      call check(error, worsth <= 1.0e-4_wp, "Hessian bound holds the second derivative along great circles")
   contains
      !> The point at arc length t from u along the great circle towards w.
      pure function arc(t) result(v)
         real(wp), intent(in) :: t
         real(wp) :: v(3)
         v = cos(t) * u + sin(t) * w
      end function arc
   end subroutine test_gradient
end module test_sh
