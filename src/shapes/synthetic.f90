!> Synthetic aggregate-like star shapes with no input files.
!>
!> Each shape is an ellipsoid with random axis ratios, expanded in SH to degree nmax, plus random
!> statistically isotropic "roughness" coefficients of degrees 3..nmax, then scaled to mean radius
!> 1 (a_00 = 2 sqrt(pi)). The axis ratios are b/c = 1 + X and a/b = 1 + Y with X and Y log-normal
!> (means and standard deviations `bc_mean`, `bc_sd`, `ab_mean`, `ab_sd`). The roughness follows
!> the degree power spectrum of the real CT particles of NIST's MA111-7-coarse set,
!> P(n) = sum_m |a_nm|^2 / a_00^2 = c n^(-beta) for n >= 3 (c = 0.244, beta = 2.85 fitted to the
!> 24 particles), times a log-normal factor per shape (spread `sigma_rough`). A draw with
!> r_min < rmin_fraction of the mean radius is rejected and redrawn. The calibration and the
!> figures it reproduces are in docs/synthetic-shapes.md.
!>
!> Shape k of a set depends only on (seed, k): shapes can be made in parallel and in any order.
!>
!> Usage:
!>     type(synthetic_params_type) :: par
!>     call make_synthetic_shape(par, seed=1_i8, index=5, shape=s, error=err)
module anm_shapes_synthetic
   use anm_core_kinds, only: wp, i8, pi
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_core_strings, only: to_string
   use anm_core_random, only: rng_type, new_rng
   use anm_sh_expansion, only: sh_expansion_type, new_sh_expansion_real
   use anm_shapes_analytic, only: ellipsoid_shape
   use anm_shapes_star, only: min_radius
   implicit none
   private

   public :: synthetic_params_type, make_synthetic_shape

   !> Parameters of the generator (defaults calibrated on MA111-7-coarse).
   type :: synthetic_params_type
      !> Highest degree of the generated expansion.
      integer :: nmax = 20
      !> Mean and standard deviation of X in b/c = 1 + X (middle over shortest semi-axis).
      real(wp) :: bc_mean = 1.10_wp, bc_sd = 0.80_wp
      !> Mean and standard deviation of Y in a/b = 1 + Y (longest over middle semi-axis).
      real(wp) :: ab_mean = 0.60_wp, ab_sd = 0.50_wp
      !> Roughness amplitude c in P(n) = c n^(-beta), n >= 3.
      real(wp) :: rough_c = 0.244_wp
      !> Roughness exponent beta.
      real(wp) :: rough_beta = 2.85_wp
      !> Log-normal spread (standard deviation of ln amplitude) of the roughness per shape.
      real(wp) :: sigma_rough = 0.5_wp
      !> Smallest accepted r_min / mean radius.
      real(wp) :: rmin_fraction = 0.2_wp
      !> Maximum draws per shape before giving up.
      integer :: max_draws = 1000
   end type synthetic_params_type

contains

   !> Make synthetic shape number `index` of the set seeded by `seed` (mean radius 1).
   subroutine make_synthetic_shape(par, seed, index, shape, error, draws)
      !> Generator parameters.
      type(synthetic_params_type), intent(in) :: par
      !> Base seed.
      integer(i8), intent(in) :: seed
      !> Shape number (>= 1); the random stream id.
      integer, intent(in) :: index
      !> Generated expansion.
      type(sh_expansion_type), intent(out) :: shape
      !> Error when no acceptable draw is found or parameters are invalid.
      type(error_type), allocatable, intent(out) :: error
      !> Number of draws used (1 = first draw accepted).
      integer, intent(out), optional :: draws
      type(rng_type) :: rng
      type(sh_expansion_type) :: ell
      real(wp), allocatable :: a(:, :), b(:, :)
      real(wp) :: a00, ampr, pn, sig, rmin, th, ph, bc, ab, norm
      integer :: n, m, k, nmax

      nmax = par%nmax
      if (nmax < 2 .or. nmax > 100) then
         call fatal_error(error, "synthetic shapes: nmax = "//to_string(nmax)//" outside 2..100", error_code%value)
         return
      end if
      if (par%rough_c < 0.0_wp .or. par%sigma_rough < 0.0_wp .or. par%bc_mean < 0.0_wp .or. par%ab_mean < 0.0_wp &
          .or. par%bc_sd < 0.0_wp .or. par%ab_sd < 0.0_wp) then
         call fatal_error(error, "synthetic shapes: rough_c, sigma_rough and the axis-ratio means and "// &
                          "standard deviations must be >= 0", error_code%value)
         return
      end if
      call new_rng(rng, seed, int(index, i8))
      allocate (a(0:nmax, 0:nmax), b(0:nmax, 0:nmax))
      a00 = 2.0_wp * sqrt(pi)
      do k = 1, par%max_draws
         bc = 1.0_wp + lognormal(par%bc_mean, par%bc_sd)
         ab = 1.0_wp + lognormal(par%ab_mean, par%ab_sd)
         ell = ellipsoid_shape(ab * bc, bc, 1.0_wp, nmax)
         norm = a00 / ell%a(0, 0)
         a = ell%a * norm
         b = ell%b * norm
         ampr = exp(par%sigma_rough * rng%normal())
         do n = 3, nmax
            pn = par%rough_c * real(n, wp)**(-par%rough_beta) * ampr
            ! isotropic: each of the 2n+1 real orthonormal components has variance P(n) a00^2/(2n+1)
            sig = sqrt(pn / (2 * n + 1)) * a00
            a(n, 0) = a(n, 0) + sig * rng%normal()
            do m = 1, n
               a(n, m) = a(n, m) + sqrt(2.0_wp) * sig * rng%normal()
               b(n, m) = b(n, m) + sqrt(2.0_wp) * sig * rng%normal()
            end do
         end do
         call new_sh_expansion_real(shape, a, b)
         call min_radius(shape, rmin, th, ph)
         if (rmin >= par%rmin_fraction) then
            if (present(draws)) draws = k
            return
         end if
      end do
      call fatal_error(error, "synthetic shape "//to_string(index)//": no star-shaped draw in " &
                       //to_string(par%max_draws)//" attempts (lower rough_c or the axis ratios)", error_code%value)
   contains
      !> Log-normal deviate with the given mean and standard deviation (0 when mean is 0).
      function lognormal(mean, sd) result(x)
         real(wp), intent(in) :: mean, sd
         real(wp) :: x, s2, mu
         if (mean <= 0.0_wp) then
            x = 0.0_wp
            return
         end if
         s2 = log(1.0_wp + (sd / mean)**2)
         mu = log(mean) - 0.5_wp * s2
         x = exp(mu + sqrt(s2) * rng%normal())
      end function lognormal
   end subroutine make_synthetic_shape
end module anm_shapes_synthetic
