use super::*;

/// Every state is kept while the run fits the budget; beyond it, checkpoints about
/// sqrt(steps) apart (1000 hammerbot steps fit, a run 10x longer does not).
#[test]
fn checkpoints_are_kept_within_the_memory_budget() {
    let hammerbot_state = 2 * 3 * 2210;
    assert_eq!(default_checkpoint_interval(1000, hammerbot_state), 1);
    assert_eq!(default_checkpoint_interval(10_000, hammerbot_state), 100);
    assert_eq!(default_checkpoint_interval(STATE_VALUES_BUDGET - 1, 1), 1);
    assert_eq!(default_checkpoint_interval(STATE_VALUES_BUDGET, 1), 8192);
}
