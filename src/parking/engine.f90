!> The parking engine (thesis section 2.1, Fig 1.3): particles are parked one at a time, largest
!> sieve first, at random locations without overlap, until each sieve's target volume is reached
!> or its attempts are exhausted.
!>
!> For each particle: up to max_shapes shapes of the sieve, for each up to max_sizes widths
!> (uniform in the sieve's range), for each up to max_orientations uniformly random rotations, for
!> each up to max_locations uniformly random centres (the thesis' four randomness sources). A
!> particle that exhausts them ends its sieve (reported as a shortfall, never an endless loop).
!> The last particle of a sieve is kept only if it brings the sieve's volume closer to its target.
!>
!> Particle i of sieve s draws every random number from its own stream (seed, s 2^32 + i): the
!> model depends only on the namelist and the seed.
!>
!> Per (sieve, shape) the engine precomputes the geometry at the sieve's order (width, length,
!> volume), the contact body and, with shells, the outer surface of every layer. With thickness
!> in mm, widths are drawn from `width_levels` equally spaced values per sieve so that shells can
!> be precomputed per (sieve, shape, width level).
!>
!> Usage:
!>     call run_parking(cfg, model, error, progress_unit=error_unit)
module anm_parking_engine
   use anm_core_kinds, only: wp, i8, pi
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_core_strings, only: to_string
   use anm_core_random, only: rng_type, new_rng
   use anm_sh_expansion, only: sh_expansion_type, sh_truncate
   use anm_shapes_library, only: shape_set_type, load_shapes, synthetic_shapes
   use anm_shapes_analytic, only: sphere_shape
   use anm_geometry_properties, only: shape_geometry_type, compute_geometry
   use anm_geometry_rotation, only: random_rotation
   use anm_contact_body, only: contact_body_type, new_contact_body
   use anm_contact_overlap, only: contact_params_type, contact_method, bodies_overlap, body_crosses_walls
   use anm_shells_build, only: shell_report_type, build_layers
   use anm_config_job, only: run_config_type, shell_mode, thickness_unit, placement, write_config
   use anm_shells_thickness, only: thickness_to_shape_units, thickness_to_mm
   use anm_parking_cell_list, only: cell_list_type, new_cell_list
   use anm_parking_void_grid, only: void_grid_type, new_void_grid
   use anm_io_model, only: model_type
   use omp_lib, only: omp_get_max_threads
   implicit none
   private

   public :: run_parking, particle_kind_type, width_levels

   !> Discrete widths per sieve when shell thickness is given in mm.
   integer, parameter :: width_levels = 8

   !> Precomputed data of one (sieve, shape[, width level]) combination.
   type :: particle_kind_type
      !> Index into the model's shapes.
      integer :: shape = 0
      !> Sieve.
      integer :: sieve = 0
      !> Order used.
      integer :: order = 0
      !> Width level (0: continuous widths).
      integer :: level = 0
      !> Geometry at the order used (shape units).
      real(wp) :: width = 0.0_wp, length = 0.0_wp, volume = 0.0_wp
      !> Bare particle.
      type(contact_body_type) :: body
      !> Particle plus its outermost shell (allocated with shells).
      type(contact_body_type), allocatable :: shell_body
      !> Outer surfaces of the layers (shape units) and the volume inside each.
      type(sh_expansion_type), allocatable :: layers(:)
      !> Volume inside each layer's outer surface (shape units).
      real(wp), allocatable :: layer_volume(:)
      !> Bounding radius of the largest body the overlap tests use (shape units).
      real(wp) :: r_out = 0.0_wp
      !> Radii (shape units) such that a particle of this kind, placed as a candidate, certainly
      !> overlaps a parked one whose centre is closer than scale r_in_query + scale_j r_in_parked
      !> (the inscribed radii of the bodies the shell mode tests: the overlap test's own first
      !> stage).
      real(wp) :: r_in_query = 0.0_wp, r_in_parked = 0.0_wp
   end type particle_kind_type

   !> The attempt sequence of one particle: the thesis' four nested randomness sources, drawn from
   !> the particle's own stream in a fixed order (shape, [width level], width, rotation, centre).
   type :: attempt_type
      type(rng_type) :: rng
      integer :: is = 0, iz = 0, io = 0, il = 0
      integer :: kk = 0, k = 0
      real(wp) :: w = 0.0_wp, sc = 0.0_wp, r(3, 3) = 0.0_wp, c(3) = 0.0_wp
      !> Attempts drawn so far.
      integer(i8) :: count = 0
      !> All attempts exhausted.
      logical :: done = .false.
   end type attempt_type

contains

   !> Build the model the configuration asks for. Progress goes to `progress_unit` (stderr in the
   !> program) about every two seconds.
   subroutine run_parking(cfg, model, kinds, kind_of, error, progress_unit, max_batch)
      !> Validated configuration.
      type(run_config_type), intent(in) :: cfg
      !> The packed model.
      type(model_type), intent(out) :: model
      !> Precomputed kinds (also used for VRML output).
      type(particle_kind_type), allocatable, intent(out) :: kinds(:)
      !> Kind of each particle.
      integer, allocatable, intent(out) :: kind_of(:)
      !> Error: a shape source cannot be read, a shell cannot be built.
      type(error_type), allocatable, intent(out) :: error
      !> Unit for progress lines (none when absent).
      integer, intent(in), optional :: progress_unit
      !> Largest batch of speculated particles (default: no limit; 1 runs the plain serial
      !> algorithm, which tests use as the reference).
      integer, intent(in), optional :: max_batch
      type(contact_params_type) :: params
      integer :: batch_limit
      type(cell_list_type) :: cl
      integer, allocatable :: first_kind(:), nkind_sieve(:)
      real(wp), allocatable :: center(:, :), rot(:, :, :), scale(:), rho(:), cand_shift(:, :)
      integer, allocatable :: sieve_of(:), cand(:)
      real(wp) :: vbox, vol, target, v, sc, rho_min
      integer(i8) :: attempts, attempts_sieve, t0, t1, tlast, rate
      integer :: s, np, k, b, nstream, nlev, np_frozen, batch, nthreads, batch_size_now
      integer(i8) :: tp1
      logical :: keep, sieve_done, moved_b
      integer :: nmoved
      integer, allocatable :: moved(:)
      logical, allocatable :: alone(:)
      real(wp), allocatable :: bx(:, :), br(:)
      type(attempt_type), allocatable :: at(:)
      type(void_grid_type) :: vg
      logical :: void
      integer :: j, npark_sieve0, failures
      real(wp) :: carry
      logical :: reached
      real(wp) :: r_in
      integer, allocatable :: same(:)
      logical, allocatable :: built(:)
      logical :: lazy
      integer :: predicted, horizon
      real(wp) :: vmean

      call prepare_kinds(cfg, model, kinds, first_kind, nkind_sieve, same, error)
      if (allocated(error)) return
      ! kinds are built when first needed: with one shape and one size per particle, each
      ! particle's kind is its stream's first draw, known before its batch runs (M_sand's two
      ! coarse sieves draw about 8 of their 24 shapes); otherwise a sieve's kinds are built when it
      ! starts
      allocate (built(size(kinds)))
      built = .false.
      lazy = cfg%parking%max_shapes == 1 .and. cfg%parking%max_sizes == 1
      params%method = cfg%parking%contact_method
      params%next = cfg%parking%n_ext
      params%nbox = cfg%parking%n_box
      params%certified = cfg%parking%certified

      nlev = 1
      if (cfg%shells%nlayer > 0 .and. cfg%shells%unit == thickness_unit%mm) nlev = width_levels
      vbox = product(cfg%box%length)
      ! a bounding radius is at least half the particle's width (every caliper dimension lies in
      ! the bounding sphere)
      rho_min = 0.5_wp * minval(cfg%sieves%min_width(:cfg%sieves%nsieve))
      call new_cell_list(cl, cfg%box%length, cfg%box%periodic, rho_min, capacity=4096)
      allocate (center(3, 4096), rot(3, 3, 4096), scale(4096), rho(4096), sieve_of(4096), kind_of(4096))
      np = 0
      attempts = 0
      allocate (model%achieved_fraction(cfg%sieves%nsieve), model%count(cfg%sieves%nsieve), model%shell_fraction(cfg%sieves%nsieve))
      model%achieved_fraction = 0.0_wp
      model%count = 0
      model%shell_fraction = 0.0_wp
      ! particles speculated per batch: any value gives the same model (see phase 2), so the batch
      ! adapts to the machine and to the sieve (next_batch)
      nthreads = omp_get_max_threads()
      batch_limit = huge(1)
      if (present(max_batch)) batch_limit = max(1, max_batch)
      batch = min(nthreads, batch_limit)
      call system_clock(t0, rate)
      tlast = t0

      void = cfg%parking%placement == placement%void
      carry = 0.0_wp
      do s = 1, cfg%sieves%nsieve
         ! a sieve that reaches its volume ends within half a particle of it; that rounding
         ! difference (either sign) moves to the next sieve so that the cumulative gradation and
         ! the total stay on target. A shortfall from exhausted attempts is not carried.
         target = max(0.0_wp, cfg%sieves%target_fraction(s) * vbox + carry)
         reached = .false.
         vol = 0.0_wp
         attempts_sieve = 0
         nstream = 0
         sieve_done = .false.
         failures = 0
         predicted = 0
         if (void .or. .not. lazy) then
            call build_kinds(cfg, model, kinds, same, built, [(k, k=first_kind(s), first_kind(s) + nkind_sieve(s) - 1)], &
                             error)
            if (allocated(error)) return
         end if
         if (void) then
            ! inscribed radius of the smallest particle this sieve can make
            r_in = huge(1.0_wp)
            do k = first_kind(s), first_kind(s) + nkind_sieve(s) - 1
               r_in = min(r_in, kinds(k)%body%r_min * cfg%sieves%min_width(s) / kinds(k)%width)
            end do
            call new_void_grid(vg, cfg%box%length, cfg%box%periodic, r_in, 2**24)
            do j = 1, np
               call block(j)
            end do
            call vg%compact()
         end if
         npark_sieve0 = np
         do while (vol < target .and. .not. sieve_done)
            ! Phase 1 (parallel): the next `batch` particles each find their first fitting attempt
            ! against the frozen packing. Phase 2 (in order): each is re-checked against the
            ! particles accepted before it in this batch and, if hit, continues its own attempt
            ! sequence. Adding particles only adds overlaps, so this is exactly the serial
            ! result whatever the batch size and the number of threads. The re-check is skipped
            ! for a particle whose bounding sphere meets no earlier one of the batch (found in
            ! parallel) nor any earlier one parked elsewhere than its phase-1 position (`moved`).
            allocate (at(batch))
            batch_size_now = batch
            if (lazy) then
               ! the kinds of this batch and of the particles the sieve will probably still need
               ! (twice the missing volume over the mean particle volume: a sphere of the mean
               ! width until particles are parked), built together so that they build in parallel
               if (model%count(s) > 0) then
                  vmean = vol / model%count(s)
               else
                  vmean = pi / 6.0_wp * (0.5_wp * (cfg%sieves%min_width(s) + cfg%sieves%max_width(s)))**3
               end if
               horizon = nstream + max(batch, nthreads + int(min(4096.0_wp, 2.0_wp * max(0.0_wp, target - vol) / vmean)))
               if (horizon > predicted) then
                  call build_kinds(cfg, model, kinds, same, built, [(first_kind_of(s, j), j=predicted + 1, horizon)], &
                                   error)
                  if (allocated(error)) return
                  predicted = horizon
               end if
            end if
            call system_clock(tp1)
            !$omp parallel do default(shared) private(b) schedule(dynamic, 1)
            do b = 1, batch
               block
                  integer, allocatable :: bcand(:)
                  real(wp), allocatable :: bshift(:, :)
                  call new_rng(at(b)%rng, cfg%run%seed, int(s, i8) * 4294967296_i8 + nstream + b)
                  do
                     call next_attempt(at(b), s)
                     if (at(b)%done) exit
                     if (fits(at(b)%k, at(b)%c, at(b)%r, at(b)%sc, 0, bcand, bshift)) exit
                  end do
               end block
            end do
            !$omp end parallel do
            call system_clock(t1)
            allocate (bx(3, batch), br(batch), alone(batch))
            do b = 1, batch
               bx(:, b) = at(b)%c
               br(b) = at(b)%sc * kinds(max(1, at(b)%k))%r_out
            end do
            call first_in_reach(bx, br, cfg%box%length, cfg%box%periodic, alone)
            np_frozen = np
            allocate (moved(batch))
            nmoved = 0
            do b = 1, batch
               nstream = nstream + 1
               moved_b = .false.
               if (.not. at(b)%done .and. (.not. alone(b) .or. near_moved(b))) then
                  if (.not. fits(at(b)%k, at(b)%c, at(b)%r, at(b)%sc, np_frozen, cand, cand_shift)) then
                     moved_b = .true.
                     do
                        call next_attempt(at(b), s)
                        if (at(b)%done) exit
                        if (fits(at(b)%k, at(b)%c, at(b)%r, at(b)%sc, 0, cand, cand_shift)) exit
                     end do
                  end if
               end if
               attempts = attempts + at(b)%count - merge(1, 0, at(b)%done)
               attempts_sieve = attempts_sieve + at(b)%count - merge(1, 0, at(b)%done)
               if (at(b)%done) then
                  ! this particle exhausted its attempts: the sieve ends after max_failures such
                  ! particles (the thesis: the first); later particles of the batch go on
                  failures = failures + 1
                  if (failures >= cfg%parking%max_failures) then
                     sieve_done = .true.
                     exit
                  end if
                  cycle
               end if
               k = at(b)%k
               sc = at(b)%sc
               v = sc**3 * kinds(k)%volume
               keep = vol + v <= target .or. (vol + v - target) <= (target - vol)
               if (.not. keep) then
                  sieve_done = .true.
                  reached = .true.
                  exit
               end if
               call add_particle(k, at(b)%c, at(b)%r, sc)
               if (moved_b) then
                  nmoved = nmoved + 1
                  moved(nmoved) = b
               end if
               vol = vol + v
               model%count(s) = model%count(s) + 1
               if (cfg%shells%nlayer > 0) model%shell_fraction(s) = model%shell_fraction(s) &
                  + sc**3 * (kinds(k)%layer_volume(cfg%shells%nlayer) - kinds(k)%volume) / vbox
               if (vol >= target) exit
            end do
            if (void) then
               do j = np_frozen + 1, np
                  call block(j)
               end do
               if (vg%stale > vg%nfree / 4) call vg%compact()
               if (vg%nfree == 0) sieve_done = .true.
            end if
            deallocate (bx, br, alone, moved)
            batch = min(batch_limit, next_batch(batch_size_now, real(t1 - tp1, wp) / rate, target - vol, vol, &
                                                model%count(s), nthreads))
            deallocate (at)
            call system_clock(t1)
            if (present(progress_unit) .and. real(t1 - tlast, wp) / rate > 2.0_wp) then
               write (progress_unit, '(a,i0,a,i0,a,f8.5,a,f8.5,a,es10.3,a)') "sieve ", s, ": placed ", model%count(s), &
                  ", fraction ", vol / vbox, " of ", cfg%sieves%target_fraction(s), ", ", &
                  real(attempts, wp) / max(1.0e-9_wp, real(t1 - t0, wp) / rate), " attempts/s"
               tlast = t1
            end if
         end do
         model%achieved_fraction(s) = vol / vbox
         reached = reached .or. vol >= target
         carry = merge(target - vol, 0.0_wp, reached)
         if (present(progress_unit)) then
            call system_clock(t1)
            write (progress_unit, '(a,i0,a,i0,a,f8.5,a,f8.5,a,i0,a,i0,a,f7.1,a)') "sieve ", s, " done: ", &
               model%count(s), " particles, fraction ", vol / vbox, " (target ", cfg%sieves%target_fraction(s), "), ", &
               attempts_sieve, " attempts, ", failures, " particles not parked, ", real(t1 - t0, wp) / rate, " s"
            if (void) write (progress_unit, '(a,i0,a,f8.5,a,es10.3,a)') "sieve ", s, ": void grid free fraction ", &
               vg%free_fraction(), " (inscribed radius ", r_in, " mm)"
            if (.not. reached .and. cfg%sieves%target_fraction(s) - vol / vbox > 0.01_wp * cfg%sieves%target_fraction(s)) then
               write (progress_unit, '(a,i0,a,f8.5,a)') "warning: sieve ", s, " ended ", &
                  cfg%sieves%target_fraction(s) - vol / vbox, " short of its target (attempts exhausted)"
            end if
         end if
      end do
      call system_clock(t1)
      ! the VRML output draws every kind
      if (cfg%output%vrml) then
         call build_kinds(cfg, model, kinds, same, built, [(k, k=1, size(kinds))], error)
         if (allocated(error)) return
      end if

      model%box = cfg%box%length
      model%periodic = cfg%box%periodic
      model%np = np
      model%center = center(:, :np)
      model%rotation = rot(:, :, :np)
      model%scale = scale(:np)
      model%sieve = sieve_of(:np)
      kind_of = kind_of(:np)
      allocate (model%shape(np), model%nmax(np), model%shell_thickness(cfg%shells%nlayer, np))
      do k = 1, np
         model%shape(k) = kinds(kind_of(k))%shape
         model%nmax(k) = kinds(kind_of(k))%order
         if (cfg%shells%nlayer > 0) then
            model%shell_thickness(:, k) = thickness_to_mm(cfg%shells%thickness, cfg%shells%unit, &
                                                          kinds(kind_of(k))%length, scale(k))
         end if
      end do
      model%min_width = cfg%sieves%min_width
      model%max_width = cfg%sieves%max_width
      model%target_fraction = cfg%sieves%target_fraction
      model%namelist = cfg%text
      model%resolved = write_config(cfg)
      model%seed = cfg%run%seed
      model%attempts = attempts
      model%wall_time = real(t1 - t0, wp) / rate
   contains

      function random_centre(gen, margin) result(x)
         type(rng_type), intent(inout) :: gen
         real(wp), intent(in) :: margin
         real(wp) :: x(3)
         integer :: d
         do d = 1, 3
            if (cfg%box%periodic) then
               x(d) = gen%uniform() * cfg%box%length(d)
            else
               x(d) = gen%uniform_range(margin, cfg%box%length(d) - margin)
            end if
         end do
      end function random_centre

      !> No overlap with the walls (non-periodic) or any parked particle with index > jmin, as the
      !> shell mode says. `cnd` and `shf` are the caller's scratch (one per thread).
      logical function fits(kn, x, rr, s_, jmin, cnd, shf) result(ok)
         integer, intent(in) :: kn, jmin
         real(wp), intent(in) :: x(3), rr(3, 3), s_
         integer, allocatable, intent(inout) :: cnd(:)
         real(wp), allocatable, intent(inout) :: shf(:, :)
         integer :: i, j, ncand, ii
         real(wp) :: xj(3)
         logical :: hit
         integer, allocatable :: order(:)
         ok = .false.
         if (.not. cfg%box%periodic .and. jmin == 0) then
            if (cfg%shells%nlayer > 0 .and. cfg%shells%mode == shell_mode%exclude) then
               if (body_crosses_walls(kinds(kn)%shell_body, x, rr, s_, cfg%box%length)) return
            else
               if (body_crosses_walls(kinds(kn)%body, x, rr, s_, cfg%box%length)) return
            end if
         end if
         call cl%neighbours(x, s_ * kinds(kn)%r_out, cnd, shf, ncand, hit, rin=s_ * kinds(kn)%r_in_query, jmin=jmin)
         if (hit) return
         call likely_first(kn, x, s_, cnd, shf, ncand, order)
         do ii = 1, ncand
            i = order(ii)
            j = cnd(i)
            xj = center(:, j) + shf(:, i)
            associate (kj => kinds(kind_of(j)))
               if (cfg%shells%nlayer == 0 .or. cfg%shells%mode == shell_mode%overlap) then
                  if (bodies_overlap(kinds(kn)%body, x, rr, s_, kj%body, xj, rot(:, :, j), scale(j), params)) return
               else if (cfg%shells%mode == shell_mode%exclude) then
                  if (bodies_overlap(kinds(kn)%shell_body, x, rr, s_, kj%shell_body, xj, rot(:, :, j), scale(j), &
                                     params)) return
               else
                  if (bodies_overlap(kinds(kn)%shell_body, x, rr, s_, kj%body, xj, rot(:, :, j), scale(j), params)) return
                  if (bodies_overlap(kinds(kn)%body, x, rr, s_, kj%shell_body, xj, rot(:, :, j), scale(j), params)) return
               end if
            end associate
         end do
         ok = .true.
      end function fits

      !> The order in which to test the candidates: the most likely overlaps first, so that an
      !> attempt that fails usually fails at its first exact test. The key is where the centre
      !> distance lies between the certain-overlap and the bounding-sphere distances (0 to 1).
      !> Short lists are sorted (insertion sort, stable); long ones are kept in their order.
      subroutine likely_first(kn, x, s_, cnd, shf, ncand, order)
         integer, intent(in) :: kn, ncand
         real(wp), intent(in) :: x(3), s_
         integer, intent(in) :: cnd(:)
         real(wp), intent(in) :: shf(:, :)
         integer, allocatable, intent(out) :: order(:)
         integer, parameter :: max_sorted = 64
         real(wp) :: key(max_sorted), kk, r_in, r_out
         integer :: i, m, j, oi
         allocate (order(ncand))
         do i = 1, ncand
            order(i) = i
         end do
         if (ncand < 2 .or. ncand > max_sorted) return
         do i = 1, ncand
            j = cnd(i)
            r_in = s_ * kinds(kn)%r_in_query + scale(j) * kinds(kind_of(j))%r_in_parked
            r_out = s_ * kinds(kn)%r_out + rho(j)
            key(i) = (norm2(center(:, j) + shf(:, i) - x) - r_in) / max(r_out - r_in, tiny(1.0_wp))
         end do
         do i = 2, ncand
            oi = order(i)
            kk = key(oi)
            m = i - 1
            do while (m >= 1)
               if (key(order(m)) <= kk) exit
               order(m + 1) = order(m)
               m = m - 1
            end do
            order(m + 1) = oi
         end do
      end subroutine likely_first

      !> True when the bounding sphere of batch particle bb (phase-1 pose) meets that of a particle
      !> of the batch parked at another pose than its phase-1 one (moved(1:nmoved)).
      logical function near_moved(bb) result(near)
         integer, intent(in) :: bb
         integer :: i, mv
         real(wp) :: d(3), lim
         near = .false.
         do i = 1, nmoved
            mv = moved(i)
            d = at(mv)%c - at(bb)%c
            if (cfg%box%periodic) d = d - cfg%box%length * anint(d / cfg%box%length)
            lim = br(bb) + at(mv)%sc * kinds(at(mv)%k)%r_out
            if (sum(d**2) < lim * lim) then
               near = .true.
               return
            end if
         end do
      end function near_moved

      !> Size of the next batch. Any size gives the same model, so it follows the machine: about
      !> `batch_seconds` of phase 1 (few synchronisations, which matters most when the cores are
      !> shared with other jobs), changing by at most a factor 2 per batch, and not much beyond the
      !> particles the sieve still needs (speculation past its end is wasted work).
      pure integer function next_batch(now, seconds, missing, vol_sieve, count_sieve, nthr) result(nb)
         integer, intent(in) :: now, count_sieve, nthr
         real(wp), intent(in) :: seconds, missing, vol_sieve
         real(wp), parameter :: batch_seconds = 0.05_wp
         integer, parameter :: max_per_thread = 1024
         real(wp) :: f, need
         f = 2.0_wp
         if (seconds > 0.0_wp) f = max(0.5_wp, min(2.0_wp, batch_seconds / seconds))
         nb = max(nthr, min(max_per_thread * nthr, nint(now * f)))
         if (count_sieve > 0) then
            need = max(0.0_wp, missing) / (vol_sieve / count_sieve)
            nb = max(nthr, min(nb, int(min(need, real(huge(1) / 2, wp))) + nthr))
         end if
      end function next_batch

      !> Advance an attempt sequence by one attempt (or mark it done).
      subroutine next_attempt(a, sv)
         type(attempt_type), intent(inout) :: a
         integer, intent(in) :: sv
         if (a%done) return
         if (a%is > 0 .and. a%il < cfg%parking%max_locations) then
            a%il = a%il + 1
         else if (a%is > 0 .and. a%io < cfg%parking%max_orientations) then
            a%io = a%io + 1
            a%il = 1
            a%r = random_rotation(a%rng)
         else if (a%is > 0 .and. a%iz < cfg%parking%max_sizes) then
            a%iz = a%iz + 1
            call new_size(a, sv)
            a%io = 1
            a%il = 1
            a%r = random_rotation(a%rng)
         else if (a%is < cfg%parking%max_shapes) then
            a%is = a%is + 1
            call pick_shape(a, sv)
            a%iz = 1
            call new_size(a, sv)
            a%io = 1
            a%il = 1
            a%r = random_rotation(a%rng)
         else
            a%done = .true.
            a%count = a%count + 1
            return
         end if
         if (void) then
            a%c = void_centre(a%rng)
         else
            a%c = random_centre(a%rng, a%sc * kinds(a%k)%body%r_min)
         end if
         a%count = a%count + 1
      end subroutine next_attempt

      !> A centre drawn uniformly from the free cells of the void grid (stale entries redrawn).
      function void_centre(gen) result(x)
         type(rng_type), intent(inout) :: gen
         real(wp) :: x(3), u(4)
         integer :: tries, q
         do tries = 1, 64
            do q = 1, 4
               u(q) = gen%uniform()
            end do
            x = vg%draw(u(1), u(2), u(3), u(4))
            if (.not. vg%is_blocked(x)) exit
         end do
      end function void_centre

      !> Block the void-grid cells made invalid by parked particle jj.
      subroutine block(jj)
         integer, intent(in) :: jj
         associate (kj => kinds(kind_of(jj)))
            call vg%block_particle(kj%body%shape, center(:, jj), rot(:, :, jj), scale(jj), scale(jj) * kj%body%r_min, &
                                   rho(jj))
         end associate
      end subroutine block

      !> Draw a shape of sieve sv for an attempt sequence.
      subroutine pick_shape(a, sv)
         type(attempt_type), intent(inout) :: a
         integer, intent(in) :: sv
         ! kinds of a sieve: nlev blocks (width levels) of its shapes
         a%kk = first_kind(sv) + a%rng%below(nkind_sieve(sv) / nlev) - 1
      end subroutine pick_shape

      !> The kind of the first attempt of particle `stream` of sieve sv (its first draws).
      integer function first_kind_of(sv, stream) result(k)
         integer, intent(in) :: sv, stream
         type(attempt_type) :: a
         call new_rng(a%rng, cfg%run%seed, int(sv, i8) * 4294967296_i8 + stream)
         call pick_shape(a, sv)
         call pick_size(a, sv)
         k = a%k
      end function first_kind_of

      !> Draw a new width (and width level) for the current shape of an attempt sequence.
      subroutine new_size(a, sv)
         type(attempt_type), intent(inout) :: a
         integer, intent(in) :: sv
         call pick_size(a, sv)
         a%sc = a%w / kinds(a%k)%width
      end subroutine new_size

      !> The draws of new_size: width level (kind) and width.
      subroutine pick_size(a, sv)
         type(attempt_type), intent(inout) :: a
         integer, intent(in) :: sv
         integer :: lev
         if (nlev > 1) then
            lev = a%rng%below(width_levels)
            a%k = a%kk + (lev - 1) * (nkind_sieve(sv) / nlev)
            a%w = cfg%sieves%min_width(sv) + (lev - 0.5_wp) * (cfg%sieves%max_width(sv) - cfg%sieves%min_width(sv)) / width_levels
         else
            a%k = a%kk
            a%w = a%rng%uniform_range(cfg%sieves%min_width(sv), cfg%sieves%max_width(sv))
         end if
      end subroutine pick_size

      subroutine add_particle(kn, x, rr, s_)
         integer, intent(in) :: kn
         real(wp), intent(in) :: x(3), rr(3, 3), s_
         if (np == size(scale)) call grow()
         np = np + 1
         center(:, np) = x
         rot(:, :, np) = rr
         scale(np) = s_
         rho(np) = s_ * kinds(kn)%r_out
         sieve_of(np) = s
         kind_of(np) = kn
         call cl%insert(np, x, rho(np), rin=s_ * kinds(kn)%r_in_parked)
      end subroutine add_particle

      subroutine grow()
         real(wp), allocatable :: c2(:, :), r2(:, :, :), s2(:), h2(:)
         integer, allocatable :: i2(:), k2(:)
         integer :: n
         n = 2 * size(scale)
         allocate (c2(3, n), r2(3, 3, n), s2(n), h2(n), i2(n), k2(n))
         c2(:, :np) = center(:, :np)
         r2(:, :, :np) = rot(:, :, :np)
         s2(:np) = scale(:np)
         h2(:np) = rho(:np)
         i2(:np) = sieve_of(:np)
         k2(:np) = kind_of(:np)
         call move_alloc(c2, center)
         call move_alloc(r2, rot)
         call move_alloc(s2, scale)
         call move_alloc(h2, rho)
         call move_alloc(i2, sieve_of)
         call move_alloc(k2, kind_of)
      end subroutine grow
   end subroutine run_parking

   !> For each sphere (centres x(:, i) in the box, radii r(i)), whether no sphere of smaller index
   !> meets it (nearest periodic image): spheres hashed into cells at least 2 max(r) wide, the 27
   !> cells around each searched in parallel.
   subroutine first_in_reach(x, r, box, periodic, alone)
      !> Centres (3, n).
      real(wp), intent(in) :: x(:, :)
      !> Radii.
      real(wp), intent(in) :: r(:)
      !> Box edges.
      real(wp), intent(in) :: box(3)
      !> Periodic boundaries.
      logical, intent(in) :: periodic
      !> No sphere of smaller index meets sphere i.
      logical, intent(out) :: alone(:)
      integer, allocatable :: cell(:, :), first(:), item(:), key(:)
      integer :: n, nc(3), nbucket, i, d
      real(wp) :: h(3)
      n = size(r)
      alone = .true.
      if (n < 2) return
      nc = max(1, int(box / max(2.0_wp * maxval(r), tiny(1.0_wp))))
      nc = min(nc, 1024)
      h = box / nc
      nbucket = 2**ceiling(log(real(2 * n, wp)) / log(2.0_wp))
      allocate (cell(3, n), key(n), first(nbucket + 1), item(n))
      do i = 1, n
         do d = 1, 3
            cell(d, i) = min(nc(d) - 1, max(0, int(x(d, i) / h(d))))
         end do
         key(i) = bucket_of(cell(:, i))
      end do
      ! counting sort by bucket, indices ascending within a bucket
      first = 0
      do i = 1, n
         first(key(i) + 1) = first(key(i) + 1) + 1
      end do
      do i = 2, nbucket + 1
         first(i) = first(i) + first(i - 1)
      end do
      do i = 1, n
         first(key(i)) = first(key(i)) + 1
         item(first(key(i))) = i
      end do
      ! first(k) now ends bucket k: bucket k is item(first(k - 1) + 1 : first(k)), bucket 1 from 1
      !$omp parallel do default(none) shared(n, x, r, box, periodic, nc, cell, first, item, alone) &
      !$omp& private(i) schedule(static)
      do i = 2, n
         alone(i) = nothing_near(i)
      end do
      !$omp end parallel do
   contains
      pure integer function bucket_of(c) result(k)
         integer, intent(in) :: c(3)
         k = 1 + iand(c(1) + 1031 * (c(2) + 1031 * c(3)), nbucket - 1)
      end function bucket_of

      logical function nothing_near(i) result(ok)
         integer, intent(in) :: i
         integer :: d1, d2, d3, c(3), k, m, j, lo
         real(wp) :: dx(3)
         ok = .true.
         do d3 = -1, 1
            do d2 = -1, 1
               do d1 = -1, 1
                  c = cell(:, i) + [d1, d2, d3]
                  if (periodic) then
                     c = modulo(c, nc)
                  else if (any(c < 0 .or. c >= nc)) then
                     cycle
                  end if
                  k = bucket_of(c)
                  lo = 1
                  if (k > 1) lo = first(k - 1) + 1
                  do m = lo, first(k)
                     j = item(m)
                     if (j >= i) exit
                     dx = x(:, j) - x(:, i)
                     if (periodic) dx = dx - box * anint(dx / box)
                     if (sum(dx**2) < (r(i) + r(j))**2) then
                        ok = .false.
                        return
                     end if
                  end do
               end do
            end do
         end do
      end function nothing_near
   end subroutine first_in_reach

   !> Load the shapes of every sieve (each distinct source once) and precompute every kind.
   subroutine prepare_kinds(cfg, model, kinds, first_kind, nkind_sieve, same, error)
      type(run_config_type), intent(in) :: cfg
      type(model_type), intent(inout) :: model
      type(particle_kind_type), allocatable, intent(out) :: kinds(:)
      integer, allocatable, intent(out) :: first_kind(:), nkind_sieve(:)
      !> The kind each kind is a copy of (itself when it is built on its own).
      integer, allocatable, intent(out) :: same(:)
      type(error_type), allocatable, intent(out) :: error
      type(shape_set_type), allocatable :: sets(:)
      integer, allocatable :: set_of(:), set_first(:)
      character(len=512), allocatable :: src(:)
      integer :: s, nset, k, i, ns, nlev, lev, total, n, j

      allocate (set_of(cfg%sieves%nsieve), src(cfg%sieves%nsieve))
      nset = 0
      do s = 1, cfg%sieves%nsieve
         set_of(s) = 0
         do i = 1, nset
            if (src(i) == cfg%sieves%source(s)) set_of(s) = i
         end do
         if (set_of(s) == 0) then
            nset = nset + 1
            src(nset) = cfg%sieves%source(s)
            set_of(s) = nset
         end if
      end do
      allocate (sets(nset), set_first(nset))
      total = 0
      do i = 1, nset
         if (trim(src(i)) == "synthetic") then
            call synthetic_shapes(cfg%synthetic%params, cfg%run%seed, cfg%synthetic%count, sets(i), error)
         else if (trim(src(i)) == "sphere") then
            allocate (sets(i)%names(1), sets(i)%shapes(1))
            sets(i)%names(1)%s = "sphere"
            sets(i)%shapes(1) = sphere_shape(1.0_wp)
         else
            call load_shapes(trim(src(i)), sets(i), error)
         end if
         if (allocated(error)) then
            error%message = cfg%file//": &sieves: source = '"//trim(src(i))//"': "//error%message
            return
         end if
         set_first(i) = total
         total = total + size(sets(i)%shapes)
      end do
      allocate (model%shapes(total), model%shape_names(total))
      do i = 1, nset
         do k = 1, size(sets(i)%shapes)
            model%shapes(set_first(i) + k) = sets(i)%shapes(k)
            model%shape_names(set_first(i) + k) = sets(i)%names(k)%s
         end do
      end do

      nlev = 1
      if (cfg%shells%nlayer > 0 .and. cfg%shells%unit == thickness_unit%mm) nlev = width_levels
      allocate (first_kind(cfg%sieves%nsieve), nkind_sieve(cfg%sieves%nsieve))
      n = 0
      do s = 1, cfg%sieves%nsieve
         first_kind(s) = n + 1
         nkind_sieve(s) = size(sets(set_of(s))%shapes) * nlev
         n = n + nkind_sieve(s)
      end do
      allocate (kinds(n))
      do s = 1, cfg%sieves%nsieve
         ns = size(sets(set_of(s))%shapes)
         do lev = 1, nlev
            do k = 1, ns
               i = first_kind(s) + (lev - 1) * ns + k - 1
               kinds(i)%shape = set_first(set_of(s)) + k
               kinds(i)%sieve = s
               kinds(i)%level = merge(lev, 0, nlev > 1)
               kinds(i)%order = model%shapes(kinds(i)%shape)%nmax
               if (cfg%sieves%order(s) >= 0) kinds(i)%order = min(cfg%sieves%order(s), kinds(i)%order)
            end do
         end do
      end do
      ! a kind equal to an earlier one (same shape and order, and with shells in mm the same width:
      ! e.g. two sieves of one source) is built once and copied (build_kinds)
      allocate (same(n))
      do i = 1, n
         same(i) = i
         do j = 1, i - 1
            if (same(j) /= j) cycle
            if (kinds(j)%shape /= kinds(i)%shape .or. kinds(j)%order /= kinds(i)%order) cycle
            if (nlev > 1) then
               if (level_width(cfg, kinds(j)) /= level_width(cfg, kinds(i))) cycle
            end if
            same(i) = j
            exit
         end do
      end do
   end subroutine prepare_kinds

   !> Build the kinds `list` that are not built yet: their originals (`same`) in parallel, then the
   !> copies. A failure (a shell that cannot be built) is returned.
   subroutine build_kinds(cfg, model, kinds, same, built, list, error)
      type(run_config_type), intent(in) :: cfg
      type(model_type), intent(in) :: model
      type(particle_kind_type), intent(inout) :: kinds(:)
      integer, intent(in) :: same(:)
      logical, intent(inout) :: built(:)
      integer, intent(in) :: list(:)
      type(error_type), allocatable, intent(out) :: error
      type(error_type), allocatable :: errs(:)
      logical, allocatable :: want(:), failed(:)
      integer, allocatable :: todo(:)
      integer :: i, k, sieve, level
      allocate (want(size(kinds)))
      want = .false.
      do i = 1, size(list)
         if (.not. built(list(i))) want(same(list(i))) = .true.
      end do
      want = want .and. .not. built
      todo = pack([(k, k=1, size(kinds))], want)
      if (size(todo) > 0) then
         allocate (errs(size(todo)), failed(size(todo)))
         failed = .false.
         !$omp parallel do default(none) shared(kinds, model, cfg, errs, failed, todo) private(i) schedule(dynamic)
         do i = 1, size(todo)
            block
               type(error_type), allocatable :: err
               associate (kd => kinds(todo(i)))
                  call prepare_one(cfg, model%shapes(kd%shape), trim(model%shape_names(kd%shape)), kd, err)
               end associate
               if (allocated(err)) then
                  failed(i) = .true.
                  errs(i) = err
               end if
            end block
         end do
         !$omp end parallel do
         do i = 1, size(todo)
            if (failed(i)) then
               call fatal_error(error, errs(i)%message, errs(i)%stat)
               return
            end if
         end do
         built(todo) = .true.
      end if
      do i = 1, size(list)
         k = list(i)
         if (built(k)) cycle
         sieve = kinds(k)%sieve
         level = kinds(k)%level
         kinds(k) = kinds(same(k))
         kinds(k)%sieve = sieve
         kinds(k)%level = level
         built(k) = .true.
      end do
   end subroutine build_kinds

   !> Width of a kind's width level (shells in mm).
   pure real(wp) function level_width(cfg, kd) result(w)
      type(run_config_type), intent(in) :: cfg
      type(particle_kind_type), intent(in) :: kd
      w = cfg%sieves%min_width(kd%sieve) + (kd%level - 0.5_wp) * (cfg%sieves%max_width(kd%sieve) - cfg%sieves%min_width(kd%sieve)) &
          / width_levels
   end function level_width

   subroutine prepare_one(cfg, shape, name, kd, error)
      type(run_config_type), intent(in) :: cfg
      type(sh_expansion_type), intent(in) :: shape
      character(len=*), intent(in) :: name
      type(particle_kind_type), intent(inout) :: kd
      type(error_type), allocatable, intent(out) :: error
      type(shape_geometry_type) :: g
      type(sh_expansion_type) :: s
      type(shell_report_type), allocatable :: reports(:)
      real(wp), allocatable :: t(:)
      real(wp) :: w, sc
      integer :: k
      s = sh_truncate(shape, kd%order)
      call compute_geometry(s, g)
      kd%width = g%width
      kd%length = g%length
      kd%volume = g%volume
      call new_contact_body(kd%body, s, error, next=cfg%parking%n_ext)
      if (allocated(error)) return
      kd%r_out = kd%body%r_max
      kd%r_in_query = kd%body%r_min
      kd%r_in_parked = kd%body%r_min
      if (cfg%shells%nlayer == 0) return
      sc = 1.0_wp
      if (cfg%shells%unit == thickness_unit%mm) then
         w = level_width(cfg, kd)
         sc = w / kd%width
      end if
      t = thickness_to_shape_units(cfg%shells%thickness, cfg%shells%unit, kd%length, sc)
      call build_layers(s, t, kd%layers, reports, error, label=name)
      if (allocated(error)) then
         error%message = cfg%file//": &shells: "//error%message
         return
      end if
      allocate (kd%layer_volume(size(t)))
      do k = 1, size(t)
         kd%layer_volume(k) = reports(k)%outer_volume
      end do
      ! overlapping shells do not take part in the parking: no contact body for them
      if (cfg%shells%mode == shell_mode%overlap) return
      allocate (kd%shell_body)
      call new_contact_body(kd%shell_body, kd%layers(size(t)), error, next=cfg%parking%n_ext)
      if (allocated(error)) return
      kd%r_out = max(kd%r_out, kd%shell_body%r_max)
      kd%r_in_query = kd%shell_body%r_min
      if (cfg%shells%mode == shell_mode%exclude) kd%r_in_parked = kd%shell_body%r_min
   end subroutine prepare_one
end module anm_parking_engine
