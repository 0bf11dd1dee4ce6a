!> Fully normalised associated Legendre functions, orthonormal on the sphere with the
!> Condon-Shortley phase: Y_n^m(theta, phi) = Pbar_n^m(cos theta) exp(i m phi), so that
!> Pbar_n^m(x) = (-1)^m sqrt((2n+1)/(4 pi) (n-m)!/(n+m)!) P_n^m(x) (scipy's sph_harm_y convention).
!>
!> Values are computed by the standard column recursion in n for fixed m, seeded by the sectoral
!> recursion in m. The sectoral seed carries a separate binary exponent, so no intermediate value
!> overflows or underflows at any degree; only final values below the double range (true values
!> < 1e-308) flush to zero.
!>
!> Storage is packed by order m: the value of (n, m), 0 <= m <= n <= nmax, is at
!> `p(table%idx(m) + n - m)`, so that for fixed m the degrees n = m..nmax are contiguous.
!>
!> Usage:
!>     table = new_legendre_table(60)
!>     call legendre_values(table, cos(theta), p)     ! p(table%idx(m) + n - m)
module anm_sh_legendre
   use anm_core_kinds, only: wp, pi
   implicit none
   private

   public :: legendre_table_type, new_legendre_table, legendre_values, legendre_theta_derivatives, &
      & packed_size

   !> Recursion coefficients for degrees up to nmax (immutable after construction, so a table may
   !> be shared by every thread).
   type :: legendre_table_type
      !> Highest degree.
      integer :: nmax = -1
      !> Start of order m in packed storage (1-based): idx(m), m = 0..nmax.
      integer, allocatable :: idx(:)
      !> Column recursion: Pbar_nm = ca(k) x Pbar_{n-1,m} - cb(k) Pbar_{n-2,m}, k = idx(m) + n - m.
      real(wp), allocatable :: ca(:), cb(:)
      !> Sectoral factors sqrt((2m+1)/(2m)), m = 1..nmax.
      real(wp), allocatable :: sect(:)
      !> (2n+1)/ca(k) for n > m (0 for n = m), packed like ca: the theta-derivative factor of
      !> sh_sum_slope, divided once here rather than at every evaluation.
      real(wp), allocatable :: dq(:)
      !> e_nm = sqrt((2n+1)(n^2-m^2)/(2n-1)) for n > m (0 for n = m), packed like ca: the
      !> theta-derivative factor of sh_sum_surface (second derivatives at a point), computed once
      !> here for the shells (anm_shells_surface) and `radius_hessian`.
      real(wp), allocatable :: enm(:)
   end type legendre_table_type

contains

   !> Number of (n, m) pairs with 0 <= m <= n <= nmax.
   elemental function packed_size(nmax) result(np)
      !> Highest degree.
      integer, intent(in) :: nmax
      integer :: np
      np = (nmax + 1) * (nmax + 2) / 2
   end function packed_size

   !> Precompute the recursion coefficients for degrees 0..nmax.
   pure function new_legendre_table(nmax) result(table)
      !> Highest degree (>= 0).
      integer, intent(in) :: nmax
      type(legendre_table_type) :: table
      integer :: n, m, k
      real(wp) :: rn, rm

      table%nmax = nmax
      allocate (table%idx(0:nmax + 1), table%ca(packed_size(nmax)), table%cb(packed_size(nmax)), &
                table%dq(packed_size(nmax)), table%enm(packed_size(nmax)))
      allocate (table%sect(max(1, nmax)))
      k = 1
      do m = 0, nmax
         table%idx(m) = k
         do n = m, nmax
            rn = real(n, wp)
            rm = real(m, wp)
            if (n >= m + 2) then
               table%ca(k) = sqrt((4.0_wp * rn * rn - 1.0_wp) / (rn * rn - rm * rm))
               table%cb(k) = sqrt((4.0_wp * rn * rn - 1.0_wp) / (rn * rn - rm * rm) &
                                  * ((rn - 1.0_wp)**2 - rm * rm) / (4.0_wp * (rn - 1.0_wp)**2 - 1.0_wp))
            else if (n == m + 1) then
               table%ca(k) = sqrt(2.0_wp * rm + 3.0_wp)
               table%cb(k) = 0.0_wp
            else
               table%ca(k) = 0.0_wp
               table%cb(k) = 0.0_wp
            end if
            table%dq(k) = 0.0_wp
            if (n > m) table%dq(k) = (2 * n + 1) / table%ca(k)
            table%enm(k) = 0.0_wp
            if (n > m) table%enm(k) = sqrt((2.0_wp * rn + 1.0_wp) * (rn * rn - rm * rm) / (2.0_wp * rn - 1.0_wp))
            k = k + 1
         end do
      end do
      table%idx(nmax + 1) = k
      table%sect = 0.0_wp
      do m = 1, nmax
         table%sect(m) = sqrt((2.0_wp * m + 1.0_wp) / (2.0_wp * m))
      end do
   end function new_legendre_table

   !> Pbar_n^m(x) for all 0 <= m <= n <= table%nmax, packed by order (see module doc).
   !> `s` is sin(theta) (default sqrt(1 - x^2)); pass it when known to avoid cancellation near the
   !> poles. A negative s (theta outside [0, pi]) multiplies order m by (-1)^m, which continues
   !> Y_n^m(theta, phi) to such angles consistently with the direction (sin t cos p, sin t sin p, cos t).
   pure subroutine legendre_values(table, x, p, s)
      !> Recursion table.
      type(legendre_table_type), intent(in) :: table
      !> cos(theta), in [-1, 1].
      real(wp), intent(in) :: x
      !> Packed values, size >= packed_size(table%nmax).
      real(wp), intent(out) :: p(:)
      !> sin(theta) (optional).
      real(wp), intent(in), optional :: s
      real(wp) :: st, pmm, v0, v1, v2
      integer :: m, n, k, k0, emm, e, nmax
      integer, parameter :: big = 480

      nmax = table%nmax
      if (present(s)) then
         st = s
      else
         st = sqrt(max(0.0_wp, (1.0_wp - x) * (1.0_wp + x)))
      end if
      pmm = 1.0_wp / sqrt(4.0_wp * pi)   ! mantissa of the sectoral value, times 2**emm
      emm = 0
      do m = 0, nmax
         if (m > 0) then
            pmm = -table%sect(m) * st * pmm
            if (pmm == 0.0_wp) then
               p(table%idx(m):table%idx(nmax + 1) - 1) = 0.0_wp
               exit
            end if
            if (abs(pmm) < 2.0_wp**(-big)) then
               pmm = scale(pmm, big)
               emm = emm - big
            end if
         end if
         k0 = table%idx(m)
         e = emm
         v1 = pmm
         p(k0) = unscaled(v1, e)
         if (m < nmax) then
            v2 = table%ca(k0 + 1) * x * v1
            p(k0 + 1) = unscaled(v2, e)
            v0 = v1
            v1 = v2
            do n = m + 2, nmax
               k = k0 + n - m
               v2 = table%ca(k) * x * v1 - table%cb(k) * v0
               v0 = v1
               v1 = v2
               if (e < 0) then
                  if (abs(v1) > 2.0_wp**big) then
                     v0 = scale(v0, -big)
                     v1 = scale(v1, -big)
                     e = e + big
                  end if
               end if
               p(k) = unscaled(v1, e)
            end do
         end if
      end do
   contains
      pure function unscaled(v, ex) result(u)
         real(wp), intent(in) :: v
         integer, intent(in) :: ex
         real(wp) :: u
         if (ex == 0) then
            u = v
         else if (exponent(v) + ex < minexponent(v)) then
            u = 0.0_wp
         else
            u = scale(v, ex)
         end if
      end function unscaled
   end subroutine legendre_values

   !> Angular derivatives from packed values computed to degree nmax + 1 (`p` from a table of
   !> degree >= nmax + 1, `tab` of that degree): for 0 <= m <= n <= nmax,
   !> dp(n,m) = d Pbar_n^m / d theta and mps(n,m) = m Pbar_n^m / sin(theta), both without division
   !> by sin(theta), so they are finite at the poles. Output is packed like a table of degree nmax.
   pure subroutine legendre_theta_derivatives(tab, p, nmax, idx_out, dp, mps)
      !> Table used to compute p (degree >= nmax + 1).
      type(legendre_table_type), intent(in) :: tab
      !> Packed values from `tab`.
      real(wp), intent(in) :: p(:)
      !> Degree of the derivative output.
      integer, intent(in) :: nmax
      !> Packed offsets of the output (idx of a table of degree nmax).
      integer, intent(in) :: idx_out(0:)
      !> d Pbar / d theta, packed.
      real(wp), intent(out) :: dp(:)
      !> m Pbar / sin(theta), packed.
      real(wp), intent(out) :: mps(:)
      integer :: n, m, k
      real(wp) :: rn, rm, up, dn

      do m = 0, nmax
         rm = real(m, wp)
         do n = m, nmax
            rn = real(n, wp)
            k = idx_out(m) + n - m
            ! d/dtheta: 1/2 [ sqrt((n-m)(n+m+1)) P_n^{m+1} - sqrt((n+m)(n-m+1)) P_n^{m-1} ],
            ! with P_n^{-1} = -P_n^{1} (Condon-Shortley, normalised).
            up = 0.0_wp
            if (m + 1 <= n) up = sqrt((rn - rm) * (rn + rm + 1.0_wp)) * p(tab%idx(m + 1) + n - m - 1)
            if (m >= 1) then
               dn = sqrt((rn + rm) * (rn - rm + 1.0_wp)) * p(tab%idx(m - 1) + n - m + 1)
            else
               dn = -sqrt(rn * (rn + 1.0_wp)) * merge(p(tab%idx(1) + n - 1), 0.0_wp, n >= 1)
            end if
            dp(k) = 0.5_wp * (up - dn)
            ! m P_n^m / sin: -1/2 sqrt((2n+1)/(2n+3)) [ sqrt((n+m+1)(n+m+2)) P_{n+1}^{m+1}
            !                                         + sqrt((n-m+1)(n-m+2)) P_{n+1}^{m-1} ]
            if (m == 0) then
               mps(k) = 0.0_wp
            else
               mps(k) = -0.5_wp * sqrt((2.0_wp * rn + 1.0_wp) / (2.0_wp * rn + 3.0_wp)) &
                        * (sqrt((rn + rm + 1.0_wp) * (rn + rm + 2.0_wp)) * p(tab%idx(m + 1) + n - m) &
                           + sqrt((rn - rm + 1.0_wp) * (rn - rm + 2.0_wp)) * p(tab%idx(m - 1) + n - m + 2))
            end if
         end do
      end do
   end subroutine legendre_theta_derivatives
end module anm_sh_legendre
